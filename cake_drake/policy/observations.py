"""What a policy sees: one dictionary per step, with LeRobot's key names.

========================== ============ ======= ==============================================
key                        dtype        shape   meaning (units, frame)
========================== ============ ======= ==============================================
``observation.state``      float32      (8,)    arm joints q1..q7 (rad), gripper width (m)
``observation.velocity``   float32      (7,)    arm joint velocities (rad/s)
``observation.ee_pose``    float32      (7,)    grasp frame ``X_WG``: x y z (m, world), then
                                                its quaternion w x y z
``observation.cubes``      float32      (N, 7)  each cube's pose, as ``ee_pose``, in the order
                                                of ``cubes``
``observation.environment_ float32      (240,)  the world and the goal as numbers, for a
state``                                         learner: the layout below
``observation.images.CAM`` uint8        (H,W,3) camera CAM's RGB image (``cameras:``)
``cubes``                  tuple[str]           the cubes' names
``task``                   str                  the goal in English ("stack a on b, ...")
``goal``                   tuple[str]           the goal's PDDL facts
``time``                   float                simulated time (s)
``step``                   int                  the policy's step, from 0
========================== ============ ======= ==============================================

``observation.environment_state`` has a fixed size whatever the problem (zero past its
cubes), so one network reads every task:

========= ======================================================================
numbers   meaning
========= ======================================================================
0-83      12 rows of 7: cube k's pose (x y z, quaternion w x y z), in the order of
          ``cubes`` (a, b, c, ...); zeros past the problem's cubes
84-239    12 rows of 13: cube k's goal support, one-hot: column j < 12 "on cube j",
          column 12 "on the table"; a row of zeros where the goal says nothing of
          cube k (or there is no cube k)
========= ======================================================================

Images are rendered only when read: a policy that reads no image costs no frame.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence

import numpy as np
from pydrake.math import RigidTransform

from cake_drake.symbolic import fact_str

#: The most cubes an observation describes (the project's largest Blocksworld).
MAX_CUBES = 12
#: Columns of a cube's goal row: the 12 cubes, then the table.
GOAL_COLUMNS = MAX_CUBES + 1
ENVIRONMENT_STATE_SIZE = MAX_CUBES * 7 + MAX_CUBES * GOAL_COLUMNS


def goal_table(cubes: Sequence[str], goal: Iterable[tuple]) -> np.ndarray:
    """(12, 13) float32: each cube's goal support, one-hot (see the module's table)."""
    index = {c: k for k, c in enumerate(cubes)}
    table = np.zeros((MAX_CUBES, GOAL_COLUMNS), np.float32)
    for fact in goal:
        if fact[0] == "on" and fact[1] in index and fact[2] in index:
            table[index[fact[1]], index[fact[2]]] = 1.0
        elif fact[0] == "on-table" and fact[1] in index:
            table[index[fact[1]], MAX_CUBES] = 1.0
    return table


def environment_state(cube_poses: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """``observation.environment_state`` from the cubes' (N, 7) poses and
    :func:`goal_table`'s (12, 13): 240 float32 (see the module's table)."""
    poses = np.zeros((MAX_CUBES, 7), np.float32)
    poses[: len(cube_poses)] = cube_poses
    return np.concatenate([poses.ravel(), goal.ravel()]).astype(np.float32, copy=False)


class Observation(Mapping):
    """One control period's observation: the numbers, and each camera's image rendered on
    its first read (then kept). Read like a dict; ``dict(obs)`` renders every image."""

    def __init__(self, values: dict, images: Mapping[str, Callable[[], np.ndarray]]) -> None:
        self._values = values
        self._render = dict(images)

    def __getitem__(self, key: str):
        if key not in self._values and key in self._render:
            self._values[key] = self._render.pop(key)()
        return self._values[key]

    def __iter__(self) -> Iterator[str]:
        yield from list(self._values)
        yield from list(self._render)

    def __len__(self) -> int:
        return len(self._values) + len(self._render)

    def __contains__(self, key: object) -> bool:
        return key in self._values or key in self._render


def pose7(X: RigidTransform) -> np.ndarray:
    """x y z and quaternion w x y z of a pose, as float32."""
    q = X.rotation().ToQuaternion()
    return np.array([*X.translation(), q.w(), q.x(), q.y(), q.z()], dtype=np.float32)


def instruction(goal: Iterable[tuple]) -> str:
    """The goal in English: "stack a on b, b on c, then put c on the table"."""
    on = sorted((f[1], f[2]) for f in goal if f[0] == "on")
    table = sorted(f[1] for f in goal if f[0] == "on-table")
    clear = sorted(f[1] for f in goal if f[0] == "clear")
    parts = [f"{a} on {b}" for a, b in on]
    text = ("stack " + ", ".join(parts)) if parts else ""
    if table:
        text += (", with " if text else "put ") + " and ".join(table) + " on the table"
    if clear:
        text += (", and " if text else "") + "nothing on " + " or ".join(clear)
    return text or "hold still"


def goal_facts(goal: Iterable[tuple]) -> tuple[str, ...]:
    return tuple(fact_str(f) for f in sorted(goal))
