"""Kept for the paths files name: :mod:`cake_drake.learning.policies.expert`'s."""

from cake_drake.learning.policies.expert import make

__all__ = ["make"]
