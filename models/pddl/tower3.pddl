; Three cubes on the table; build the tower a-b-c with c on the table.
; The learning task tower3 jitters where each cube starts (world.placement).
(define (problem tower-3)
  (:domain blocksworld)
  (:objects a b c)
  (:init (on-table a) (on-table b) (on-table c) (clear a) (clear b) (clear c) (arm-empty))
  (:goal (and (on a b) (on b c) (on-table c))))
