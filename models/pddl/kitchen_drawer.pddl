; Task "put an item in a drawer": put the chips (left on the table) away in the top
; drawer and close it. With one arm the drawer can only be opened with a free hand.
(define (problem kitchen-drawer)
  (:domain kitchen)
  (:objects
    far-counter near-counter table trash-area - location
    coke-can sprite-can water-bottle apple chips energy-bar granola-bar sponge - item
    top-drawer bottom-drawer trash-can - container)
  (:init
    (at-location robot near-counter)
    (hand-empty)
    ; the chips were left on the table; the rest as usual
    (at-location coke-can far-counter) (at-location sprite-can far-counter)
    (at-location water-bottle far-counter) (at-location apple far-counter)
    (at-location chips table) (at-location sponge near-counter)
    (at-location energy-bar table)
    ; two drawers under the near counter, both closed; a granola bar in the top one
    (container-at top-drawer near-counter) (openable top-drawer) (is-closed top-drawer)
    (container-at bottom-drawer near-counter) (openable bottom-drawer) (is-closed bottom-drawer)
    (contains top-drawer granola-bar)
    ; an open trash can with no lid
    (container-at trash-can trash-area) (is-open trash-can)
    (can-wipe sponge))
  (:goal (and (contains top-drawer chips) (is-closed top-drawer))))
