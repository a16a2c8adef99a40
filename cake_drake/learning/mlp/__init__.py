"""Kept for the paths files name: :mod:`cake_drake.learning.policies.mlp`'s
(``configuration_mlp``, which checkpoints written before the move name)."""
