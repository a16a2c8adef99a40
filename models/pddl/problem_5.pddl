; The five-block problem of Exercise 4.x.1: two towers, a-b-c and d-e, are
; restacked into one column a-b-c-d-e with e on the table.
; The shortest plan has 10 actions (A*+LM-cut proves it); a satisficing
; planner may return a longer one (greedy best-first with hFF returns 14).
(define (problem problem-5)
  (:domain blocksworld)
  (:objects a b c d e)
  (:init
    (on a b) (on b c) (on-table c)
    (on d e) (on-table e)
    (clear a) (clear d)
    (arm-empty))
  (:goal (and (on a b) (on b c) (on c d) (on d e) (on-table e))))
