; The Blocksworld structure under names of its own: no predicate or action is called
; what ../blocksworld.pddl calls it, two actions take the support block first, and a
; static (cube ?x) precondition marks what may be grasped. cake_drake reads what each
; action does from its add and delete lists, so this domain runs like the others.
(define (domain cube-stacking)
  (:requirements :strips)
  (:predicates (atop ?top ?below) (on-floor ?c) (free ?c) (grasped ?c) (gripper-free)
               (cube ?c))

  (:action grasp-from-floor
    :parameters (?c)
    :precondition (and (cube ?c) (free ?c) (on-floor ?c) (gripper-free))
    :effect (and (grasped ?c) (not (free ?c)) (not (on-floor ?c)) (not (gripper-free))))

  (:action release-on-floor
    :parameters (?c)
    :precondition (grasped ?c)
    :effect (and (on-floor ?c) (free ?c) (gripper-free) (not (grasped ?c))))

  (:action place-onto
    :parameters (?below ?c)
    :precondition (and (grasped ?c) (free ?below))
    :effect (and (atop ?c ?below) (free ?c) (gripper-free)
                 (not (grasped ?c)) (not (free ?below))))

  (:action lift-off
    :parameters (?below ?c)
    :precondition (and (cube ?c) (atop ?c ?below) (free ?c) (gripper-free))
    :effect (and (grasped ?c) (free ?below)
                 (not (atop ?c ?below)) (not (free ?c)) (not (gripper-free)))))
