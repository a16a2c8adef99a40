; The exercise's five blocks for models/pddl/variants/blocksworld-renamed.pddl, whose
; predicates and actions all have names of their own.
(define (problem renamed-5)
  (:domain cube-stacking)
  (:objects a b c d e)
  (:init (cube a) (cube b) (cube c) (cube d) (cube e)
         (on-floor c) (atop b c) (atop a b) (free a) (on-floor e) (atop d e) (free d)
         (gripper-free))
  (:goal (and (on-floor e) (atop d e) (atop c d) (atop b c) (atop a b))))
