"""What a step is worth to reinforcement learning: reward terms read from the measured world.

The reward of a step is the weighted sum of these terms (the weights are scenario data:
a task's ``training.rl.reward``, :class:`cake_drake.scenario.Reward`, or the Gym env's
``reward=`` mapping). Each term is a number from 0 to 1 computed from what the policy
slot measured this period (the cubes' poses, the grasp frame, the goal's reading):

==========  =================================================================================
``goal``    the fraction of the goal's facts measured true (the Gym env's reward by default)
``success`` 1 at the step the goal is reached: every fact, every stack within 5 mm
``reach``   the hand's nearness to the first cube the goal still wants moved (its ``on``
            facts in order): 1 - tanh(d / 20 cm), d the grasp frame's distance from its
            centre (1 there, 0.24 at 20 cm; never quite 0, so a learner far away is
            still told which way is better)
``lift``    how far the cubes the goal still wants moved stand above where they began,
            1 from one cube's height up (their mean)
``place``   each goal-stacked cube's horizontal alignment over the one it goes on while it is
            above that one (carried, or resting on it): 1 centred, 0 from 10 mm (their mean)
``step``    1 every step: with a negative weight, the cost of time
``lost``    1 at the step a cube leaves the table (the episode ends there)
==========  =================================================================================

``goal`` and ``success`` are the task; ``reach`` and ``lift`` lead a learner from scratch
to the cube; ``place`` pays for the last millimetres, which the goal's reading only pays
for once they are all there. An episode ends at success, so terms paid every step must
not outweigh ending it: a ``step`` cost at least as large as the others' weights makes
lingering a loss, and a ``lost`` penalty larger than the cost of the rest of the budget
keeps throwing a cube off the table from being a way out.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, fields

import numpy as np

from cake_drake.errors import InputError
from cake_drake.scenario import Reward
from cake_drake.world.scene import CUBE_SIZE

TERMS = tuple(f.name for f in fields(Reward))
#: ``reach``: the distance scale (m) of the hand's nearness, 1 - tanh(d / REACH_RANGE).
REACH_RANGE = 0.20
#: ``place``: the horizontal offset (m) from which a cube earns nothing.
PLACE_RANGE = 0.010


def check_reward(weights: Reward | Mapping, where: str = "reward") -> Reward:
    """``weights`` as a :class:`Reward` (a term left out keeps its default: ``goal`` 1,
    the others 0): known terms, finite numbers, not all zero; one line naming the term
    otherwise."""
    if isinstance(weights, Reward):
        weights = asdict(weights)
    if not isinstance(weights, Mapping):
        raise InputError(f"{where} = {weights!r:.40}: a mapping of term -> weight "
                         f"(terms: {', '.join(TERMS)})")  # fmt: skip
    for name, value in weights.items():
        if name not in TERMS:
            raise InputError(f"{where}.{name}: no such reward term; the terms: {', '.join(TERMS)}")
        number = isinstance(value, int | float | np.floating | np.integer)
        if not number or isinstance(value, bool) or not math.isfinite(float(value)):
            raise InputError(f"{where}.{name} = {value!r:.40}: a weight is a finite number")
    reward = Reward(**{name: float(value) for name, value in weights.items()})
    if not any(asdict(reward).values()):
        raise InputError(f"{where}: every weight is 0; give at least one term a weight")
    return reward


def terms(
    progress, goal: frozenset, names: list[str], positions: np.ndarray, hand: np.ndarray,
    start_z: np.ndarray,
) -> dict[str, float]:  # fmt: skip
    """Every term of one step: ``progress`` is the goal's reading (``GoalReading``),
    ``names`` the cubes in the order of ``positions`` (N, 3, m), ``hand`` the grasp
    frame's position and ``start_z`` each cube's height when the episode began."""
    index = {n: k for k, n in enumerate(names)}
    stacks = sorted(f for f in goal if f[0] == "on")
    moving = [f for f in stacks if f in progress.missing]
    out = {"goal": progress.reward(goal), "success": float(progress.reached), "step": 1.0,
           "lost": float(progress.lost)}  # fmt: skip
    if moving:
        cube = positions[index[moving[0][1]]]
        out["reach"] = 1.0 - math.tanh(float(np.linalg.norm(hand - cube)) / REACH_RANGE)
        rise = [(positions[index[f[1]]][2] - start_z[index[f[1]]]) / CUBE_SIZE for f in moving]
        out["lift"] = float(np.mean(np.clip(rise, 0.0, 1.0)))
    else:  # nothing left to move: as much as these terms give
        out["reach"] = out["lift"] = 1.0
    aligned = []
    for _, top, below in stacks:
        p, q = positions[index[top]], positions[index[below]]
        above = p[2] - q[2] > CUBE_SIZE / 2
        offset = float(np.hypot(*(p[:2] - q[:2])))
        aligned.append(max(0.0, 1.0 - offset / PLACE_RANGE) if above else 0.0)
    out["place"] = float(np.mean(aligned)) if aligned else 1.0
    return out


def weighted(reward: Reward, values: Mapping[str, float]) -> float:
    """The step's reward: the terms weighed by ``reward``."""
    return float(sum(getattr(reward, name) * values[name] for name in TERMS))
