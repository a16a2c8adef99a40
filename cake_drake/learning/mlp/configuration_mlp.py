"""Kept for the paths files name: :mod:`cake_drake.learning.policies.mlp.configuration_mlp`."""

from cake_drake.learning.policies.mlp.configuration_mlp import CakeMLPConfig

__all__ = ["CakeMLPConfig"]
