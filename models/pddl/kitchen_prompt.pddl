; SayCan's kitchen (kitchen_default.pddl) with the things its planning prompt's few-shot
; examples name but the kitchen does not hold (Ahn et al., 2022, Appendix D.3: a sprite
; can, a mountain dew, grapes, cheese, a coffee cup). The prompt's own example plans run
; against this problem; in the default kitchen they stop at "no such object", which is a
; finding in itself: the examples were written for a kitchen the robot never saw.
(define (problem kitchen-saycan-prompt)
  (:domain kitchen)
  (:objects
    close-counter far-counter table trash-area bowl-area sink-area - location
    seven-up apple tea multigrain-chips kettle-chips jalapeno-chips rice-chips coke
    grapefruit-soda pepsi redbull energy-bar lime-soda sponge water-bottle - item
    sprite mountain-dew grapes cheese coffee-cup - item
    trash-can bowl sink top-drawer bottom-drawer - container)
  (:init
    (at-location robot close-counter)
    (hand-empty)
    (at-location seven-up far-counter) (at-location coke far-counter)
    (at-location pepsi far-counter)
    (at-location redbull far-counter) (at-location lime-soda far-counter)
    (at-location tea far-counter) (at-location water-bottle far-counter)
    (at-location multigrain-chips close-counter) (at-location kettle-chips close-counter)
    (at-location jalapeno-chips close-counter) (at-location rice-chips close-counter)
    (at-location sponge close-counter)
    (at-location apple table) (at-location energy-bar table)
    (at-location grapefruit-soda table)  ; SayCan's example moves it "from the table"
    ; the prompt's extra things: the finished drink and the cup on the table, the rest
    ; with the drinks and the fruit
    (at-location sprite table) (at-location coffee-cup table)
    (at-location mountain-dew far-counter) (at-location cheese far-counter)
    (at-location grapes close-counter)
    (container-at trash-can trash-area) (is-open trash-can)
    (container-at bowl bowl-area) (is-open bowl)
    (container-at sink sink-area) (is-open sink)
    (container-at top-drawer close-counter) (openable top-drawer) (is-closed top-drawer)
    (container-at bottom-drawer close-counter) (openable bottom-drawer) (is-closed bottom-drawer)
    (can-wipe sponge)))
