"""The learned layer's slot: what a policy sees, how its actions are read, and the
Gymnasium environment built on the same Diagram (:mod:`cake_drake.gym`)."""
