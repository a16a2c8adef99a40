; Two cubes on the table; put a on b (ManiSkill's StackCube, as a Blocksworld problem).
; The learning task stack2 jitters where each cube starts (world.placement).
(define (problem stack-2)
  (:domain blocksworld)
  (:objects a b)
  (:init (on-table a) (on-table b) (clear a) (clear b) (arm-empty))
  (:goal (and (on a b) (on-table b))))
