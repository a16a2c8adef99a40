; An IPC-2000-style Blocksworld problem, written as the competition wrote them:
; upper case, letters for objects, a partial goal (only ON facts). For the domain
; models/pddl/variants/blocksworld-ipc.pddl (domain BLOCKS).
(define (problem BLOCKS-4-0)
(:domain BLOCKS)
(:objects D B A C )
(:INIT (CLEAR C) (CLEAR A) (CLEAR B) (CLEAR D) (ONTABLE C) (ONTABLE A)
 (ONTABLE B) (ONTABLE D) (HANDEMPTY))
(:goal (AND (ON D C) (ON C B) (ON B A)))
)
