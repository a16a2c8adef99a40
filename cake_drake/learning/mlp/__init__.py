"""Kept for the paths files name: :mod:`cake_drake.learning.policies.mlp`'s."""
