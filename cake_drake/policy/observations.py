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
``observation.images.CAM`` uint8        (H,W,3) camera CAM's RGB image (``cameras:``)
``cubes``                  tuple[str]           the cubes' names
``task``                   str                  the goal in English ("stack a on b, ...")
``goal``                   tuple[str]           the goal's PDDL facts
``time``                   float                simulated time (s)
``step``                   int                  the policy's step, from 0
========================== ============ ======= ==============================================
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from pydrake.math import RigidTransform

from cake_drake.symbolic import fact_str


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
