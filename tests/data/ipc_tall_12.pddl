; Twelve blocks b1 ... b12 in IPC naming: a tower ten high (b1 at the bottom, b10 on
; top) and b11, b12 on the table; the goal is a tower nine high on b11, b10 lowest,
; and says nothing about b1, b2 and b12. For models/pddl/variants/blocksworld-ipc.pddl.
(define (problem tall-12)
  (:domain blocks)
  (:objects b1 b2 b3 b4 b5 b6 b7 b8 b9 b10 b11 b12)
  (:init (ontable b1) (on b2 b1) (on b3 b2) (on b4 b3) (on b5 b4) (on b6 b5) (on b7 b6)
         (on b8 b7) (on b9 b8) (on b10 b9) (clear b10)
         (ontable b11) (clear b11) (ontable b12) (clear b12) (handempty))
  (:goal (and (on b10 b11) (on b9 b10) (on b8 b9) (on b7 b8) (on b6 b7) (on b5 b6)
              (on b4 b5) (on b3 b4))))
