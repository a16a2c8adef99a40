; Blocksworld with one classic mistake: pick-up lacks the precondition (arm-empty)
(define (domain blocksworld)
  (:requirements :strips)
  (:predicates
    (on ?x ?y)        ; block ?x sits directly on block ?y
    (on-table ?x)     ; block ?x sits on the table
    (clear ?x)        ; nothing is on ?x and the arm does not hold it
    (holding ?x)      ; the arm holds ?x
    (arm-empty))      ; the arm holds nothing

  (:action pick-up
    :parameters (?x)
    :precondition (and (clear ?x) (on-table ?x))
    :effect (and (holding ?x)
                 (not (clear ?x)) (not (on-table ?x)) (not (arm-empty))))

  (:action put-down
    :parameters (?x)
    :precondition (holding ?x)
    :effect (and (clear ?x) (on-table ?x) (arm-empty)
                 (not (holding ?x))))

  (:action stack
    :parameters (?x ?y)
    :precondition (and (holding ?x) (clear ?y))
    :effect (and (on ?x ?y) (clear ?x) (arm-empty)
                 (not (holding ?x)) (not (clear ?y))))

  (:action unstack
    :parameters (?x ?y)
    :precondition (and (on ?x ?y) (clear ?x) (arm-empty))
    :effect (and (holding ?x) (clear ?y)
                 (not (on ?x ?y)) (not (clear ?x)) (not (arm-empty)))))
