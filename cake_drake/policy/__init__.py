"""The learned layer's slot, as the Diagram sees it: what a policy observes
(:mod:`~cake_drake.policy.observations`), what its action means
(:mod:`~cake_drake.policy.spaces`) and the shield's named steps around a learned skill
(:mod:`~cake_drake.policy.shield`). Episodes, datasets, training and evaluation live one
layer up, in :mod:`cake_drake.learning`."""
