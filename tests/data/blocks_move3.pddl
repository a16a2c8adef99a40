; Blocksworld with three "move" operators and no arm (as in some planning textbooks):
; a block goes from one place to another in one action and is never held. The robot
; needs to know what it grasps and where it lets go, so cake_drake refuses this domain.
(define (domain blocks-move)
  (:requirements :strips)
  (:predicates (on ?x ?y) (ontable ?x) (clear ?x))
  (:action move-b-to-b
    :parameters (?b ?from ?to)
    :precondition (and (clear ?b) (clear ?to) (on ?b ?from))
    :effect (and (on ?b ?to) (clear ?from) (not (on ?b ?from)) (not (clear ?to))))
  (:action move-b-to-t
    :parameters (?b ?from)
    :precondition (and (clear ?b) (on ?b ?from))
    :effect (and (ontable ?b) (clear ?from) (not (on ?b ?from))))
  (:action move-t-to-b
    :parameters (?b ?to)
    :precondition (and (clear ?b) (clear ?to) (ontable ?b))
    :effect (and (on ?b ?to) (not (clear ?to)) (not (ontable ?b)))))
