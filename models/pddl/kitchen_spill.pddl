; Task "clean up a spill" (a teaching case of our own): in SayCan's kitchen the user
; knocked the coke over on the table. Goal: the spill wiped and the can in the trash.
; SayCan has no wiping skill; this domain does, to show a decomposition.
(define (problem kitchen-spill)
  (:domain kitchen)
  (:objects
    close-counter far-counter table trash-area bowl-area sink-area - location
    seven-up apple tea multigrain-chips kettle-chips jalapeno-chips rice-chips coke
    grapefruit-soda pepsi redbull energy-bar lime-soda sponge water-bottle - item
    spill - mess
    trash-can bowl sink top-drawer bottom-drawer - container)
  (:init
    (at-location robot close-counter)
    (hand-empty)
    ; drinks on the far counter (but the grapefruit soda)
    (at-location seven-up far-counter)
    ; the coke lies knocked over in a spill on the table
    (at-location coke table) (at-location spill table)
    (at-location pepsi far-counter)
    (at-location redbull far-counter) (at-location lime-soda far-counter)
    (at-location tea far-counter) (at-location water-bottle far-counter)
    ; chips and the sponge on the close counter, fruit and the energy bar on the table
    (at-location multigrain-chips close-counter) (at-location kettle-chips close-counter)
    (at-location jalapeno-chips close-counter) (at-location rice-chips close-counter)
    (at-location sponge close-counter)
    (at-location apple table) (at-location energy-bar table)
    (at-location grapefruit-soda table)  ; SayCan's example moves it "from the table"
    ; containers without lids, each at its own place (SayCan treats them as locations)
    (container-at trash-can trash-area) (is-open trash-can)
    (container-at bowl bowl-area) (is-open bowl)
    (container-at sink sink-area) (is-open sink)
    ; two drawers under the close counter, both closed
    (container-at top-drawer close-counter) (openable top-drawer) (is-closed top-drawer)
    (container-at bottom-drawer close-counter) (openable bottom-drawer) (is-closed bottom-drawer)
    (can-wipe sponge))
  (:goal (and (cleaned spill) (contains trash-can coke))))
