; Task "clean up a spill": the user knocked a coke can over on the table. Goal: the
; spill wiped and the can in the trash.
(define (problem kitchen-spill)
  (:domain kitchen)
  (:objects
    far-counter near-counter table trash-area - location
    coke-can sprite-can water-bottle apple chips energy-bar granola-bar sponge - item
    spill - mess
    top-drawer bottom-drawer trash-can - container)
  (:init
    (at-location robot near-counter)
    (hand-empty)
    ; the coke can lies knocked over in a spill on the table; the rest as usual
    (at-location coke-can table) (at-location spill table) (at-location sprite-can far-counter)
    (at-location water-bottle far-counter) (at-location apple far-counter)
    (at-location chips near-counter) (at-location sponge near-counter)
    (at-location energy-bar table)
    ; two drawers under the near counter, both closed; a granola bar in the top one
    (container-at top-drawer near-counter) (openable top-drawer) (is-closed top-drawer)
    (container-at bottom-drawer near-counter) (openable bottom-drawer) (is-closed bottom-drawer)
    (contains top-drawer granola-bar)
    ; an open trash can with no lid
    (container-at trash-can trash-area) (is-open trash-can)
    (can-wipe sponge))
  (:goal (and (cleaned spill) (contains trash-can coke-can))))
