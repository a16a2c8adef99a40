; The exercise's five blocks (towers a-b-c and d-e, goal one column a-b-c-d-e) for
; the typed variant models/pddl/variants/blocksworld-typed.pddl.
(define (problem typed-5)
  (:domain blocks-typed)
  (:objects a b c d e - block)
  (:init (ontable c) (on b c) (on a b) (clear a) (ontable e) (on d e) (clear d) (handempty))
  (:goal (and (ontable e) (on d e) (on c d) (on b c) (on a b))))
