"""Kept for the paths files name: :mod:`cake_drake.learning.envs.lerobot_env` (registers it)."""

from cake_drake.learning.envs.lerobot_env import CakeDrakeEnv

__all__ = ["CakeDrakeEnv"]
