; The default kitchen of the language-plan tool, modelled on the office kitchen SayCan
; was evaluated in: two counters, a table, drawers, a trash can, the user, and the
; usual drinks and snacks. It has no goal: with it, `python -m cake_drake.saycan`
; checks that every step of a transcript can be executed and reports the state reached.
; kitchen_snack/spill/drawer.pddl are the same kitchen with a task as the goal.
(define (problem kitchen-default)
  (:domain kitchen)
  (:objects
    far-counter near-counter table trash-area - location
    coke-can sprite-can water-bottle apple chips energy-bar granola-bar sponge - item
    top-drawer bottom-drawer trash-can - container)
  (:init
    (at-location robot near-counter)
    (hand-empty)
    ; drinks and an apple on the far counter, chips and the sponge on the near counter
    (at-location coke-can far-counter) (at-location sprite-can far-counter)
    (at-location water-bottle far-counter) (at-location apple far-counter)
    (at-location chips near-counter) (at-location sponge near-counter)
    (at-location energy-bar table)
    ; two drawers under the near counter, both closed; a granola bar in the top one
    (container-at top-drawer near-counter) (openable top-drawer) (is-closed top-drawer)
    (container-at bottom-drawer near-counter) (openable bottom-drawer) (is-closed bottom-drawer)
    (contains top-drawer granola-bar)
    ; an open trash can with no lid
    (container-at trash-can trash-area) (is-open trash-can)
    (can-wipe sponge)))
