; The default kitchen of the language-plan tool: SayCan's office kitchen (Ahn et al.,
; 2022, arXiv:2204.01691). Its 15 objects and its locations are the ones the paper's
; chain-of-thought prompt lists (Appendix E.4, Listing 3: "7up, apple, tea, multigrain
; chips, kettle chips, jalapeno chips, rice chips, coke, grapefruit soda, pepsi, redbull,
; energy bar, lime soda, sponge, and water bottle"; "close counter, far counter, table,
; you, trash, bowl"), plus the drawers of its drawer-manipulation skills and the sink its
; planning prompt mentions. The paper gives no layout: where each thing stands is ours.
; It has no goal: `python -m cake_drake.saycan` takes the goal from the transcript's
; `Goal:` line, or only checks that each step executes.
(define (problem kitchen-saycan)
  (:domain kitchen)
  (:objects
    close-counter far-counter table trash-area bowl-area sink-area - location
    seven-up apple tea multigrain-chips kettle-chips jalapeno-chips rice-chips coke
    grapefruit-soda pepsi redbull energy-bar lime-soda sponge water-bottle - item
    trash-can bowl sink top-drawer bottom-drawer - container)
  (:init
    (at-location robot close-counter)
    (hand-empty)
    ; drinks on the far counter (but the grapefruit soda)
    (at-location seven-up far-counter) (at-location coke far-counter)
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
    (can-wipe sponge)))
