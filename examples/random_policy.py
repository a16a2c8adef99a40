"""A policy plug-in that fails: uniform random actions within the action space's bounds.

The baseline that shows the success measure can fail (it never builds a tower). Seeded
at ``reset``: the same seed gives the same actions. Use it:
``reference: !Policy {factory: examples.random_policy:make, action_space: ee_delta}``.
"""

from __future__ import annotations

import numpy as np

from cake_drake.geometric.ik import Kinematics
from cake_drake.policy.spaces import bounds


class RandomPolicy:
    def __init__(self) -> None:
        kin = Kinematics()
        self.lower, self.upper = kin.lower, kin.upper

    def reset(self, task, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.low, self.high = bounds(task.action_space, task.options or {}, self.lower, self.upper)

    def act(self, observation: dict) -> np.ndarray:
        return self.rng.uniform(self.low, self.high)


def make(**options) -> RandomPolicy:
    return RandomPolicy(**options)
