"""Kept for the paths files name: :mod:`cake_drake.learning.policies.skills`'s."""

from cake_drake.learning.policies.skills import check_folder, describe, make, under_expert

__all__ = ["check_folder", "describe", "make", "under_expert"]
