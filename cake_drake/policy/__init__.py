"""The learned layer's slot, as the Diagram sees it: what a policy observes
(:mod:`~cake_drake.policy.observations`) and what its action means
(:mod:`~cake_drake.policy.spaces`). Episodes, datasets, training and evaluation live one
layer up, in :mod:`cake_drake.learning`."""
