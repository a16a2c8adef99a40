; An office kitchen for a one-armed mobile manipulator, in the skill vocabulary of
; SayCan (Ahn et al., 2022): find, go to, pick up, put down, bring it to you, open,
; close, put in, wipe. STRIPS with types; written for cake_drake's language-plan tool
; (python -m cake_drake.saycan), which maps transcript steps onto these actions.
(define (domain kitchen)
  (:requirements :strips :typing)
  (:types
    location - object       ; where the robot and things can be: counters, table, user
    locatable - object      ; things with an at-location
    robot item mess - locatable
    container - object)     ; drawers and the trash can; each stands at a location

  (:constants robot - robot  user - location)

  (:predicates
    (at-location ?x - locatable ?l - location)  ; the robot, an item or a mess is at ?l
    (in-hand ?i - item)                         ; the gripper holds ?i
    (hand-empty)
    (container-at ?c - container ?l - location) ; static: where a container stands
    (contains ?c - container ?i - item)         ; ?i is inside ?c
    (is-open ?c - container)
    (is-closed ?c - container)
    (openable ?c - container)                   ; static: drawers yes, the trash can no
    (can-wipe ?i - item)                        ; static: a sponge, a towel
    (cleaned ?m - mess))

  ; "go to the table"
  (:action go-to
    :parameters (?from ?to - location)
    :precondition (at-location robot ?from)
    :effect (and (at-location robot ?to) (not (at-location robot ?from))))

  ; "find an apple": drive to where the item is in plain view (not inside a container)
  (:action find
    :parameters (?i - item ?from ?to - location)
    :precondition (and (at-location robot ?from) (at-location ?i ?to))
    :effect (and (at-location robot ?to) (not (at-location robot ?from))))

  ; "pick up the apple" from a counter or the table
  (:action pick-up
    :parameters (?i - item ?l - location)
    :precondition (and (at-location robot ?l) (at-location ?i ?l) (hand-empty))
    :effect (and (in-hand ?i) (not (at-location ?i ?l)) (not (hand-empty))))

  ; "pick up the chips" out of an open drawer
  (:action take-out
    :parameters (?i - item ?c - container ?l - location)
    :precondition (and (at-location robot ?l) (container-at ?c ?l) (is-open ?c)
                       (contains ?c ?i) (hand-empty))
    :effect (and (in-hand ?i) (not (contains ?c ?i)) (not (hand-empty))))

  ; "put down the apple"
  (:action put-down
    :parameters (?i - item ?l - location)
    :precondition (and (in-hand ?i) (at-location robot ?l))
    :effect (and (at-location ?i ?l) (hand-empty) (not (in-hand ?i))))

  ; "put the chips in the drawer", "throw the can in the trash"
  (:action put-in
    :parameters (?i - item ?c - container ?l - location)
    :precondition (and (in-hand ?i) (at-location robot ?l) (container-at ?c ?l) (is-open ?c))
    :effect (and (contains ?c ?i) (hand-empty) (not (in-hand ?i))))

  ; "bring it to you": carry the held item to the user
  (:action bring-to-user
    :parameters (?i - item ?from - location)
    :precondition (and (in-hand ?i) (at-location robot ?from))
    :effect (and (at-location robot user) (not (at-location robot ?from))))

  ; "open the top drawer" (one arm: the hand must be free)
  (:action open
    :parameters (?c - container ?l - location)
    :precondition (and (at-location robot ?l) (container-at ?c ?l) (openable ?c)
                       (is-closed ?c) (hand-empty))
    :effect (and (is-open ?c) (not (is-closed ?c))))

  ; "close the top drawer"
  (:action close
    :parameters (?c - container ?l - location)
    :precondition (and (at-location robot ?l) (container-at ?c ?l) (openable ?c)
                       (is-open ?c) (hand-empty))
    :effect (and (is-closed ?c) (not (is-open ?c))))

  ; "wipe the spill" with a held sponge
  (:action wipe
    :parameters (?m - mess ?i - item ?l - location)
    :precondition (and (at-location robot ?l) (at-location ?m ?l) (in-hand ?i) (can-wipe ?i))
    :effect (and (cleaned ?m) (not (at-location ?m ?l)))))
