"""Kept for the paths files name: :mod:`cake_drake.learning.policies.checkpoint`'s."""

from cake_drake.learning.policies.checkpoint import (
    check_folder,
    describe,
    is_skill_folder,
    make,
    sees,
)

__all__ = ["check_folder", "describe", "is_skill_folder", "make", "sees"]
