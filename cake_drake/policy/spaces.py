"""Action spaces: what a policy's action means, and how it becomes a joint target.

Each space is one documented convention; the policy's action (a numpy array) is checked
(shape, finite) and clipped to its bounds, then turned into 7 joint targets and a gripper
width that the controller holds until the next step:

``joint_position`` (8,)
    Seven absolute joint angles (rad) and the gripper width between the fingers (m, 0 to
    0.08). Clipped to the arm's joint limits and the gripper's range.
``ee_delta`` (7,)
    OpenVLA/Bridge style: a move of the grasp frame (between the fingertips) from where it
    is measured now, dx dy dz (m, world frame, at most 0.05 each) and droll dpitch dyaw
    (rad, about world axes through the grasp point, at most 0.25 each), then the gripper,
    0 closed to 1 open. The target pose goes through damped least squares on Drake's
    kinematics (:class:`cake_drake.geometric.ik.DlsIk`, at most 50 iterations, seeded at
    the last target: a step is small); a pose it cannot reach keeps the last target and
    is counted.
``joint_chunk`` (H, 8)
    pi0 style: H rows of ``joint_position`` actions at the control rate; the first
    ``execute`` rows (an option, default all) are executed before the policy is asked
    again.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw

from cake_drake.errors import InputError
from cake_drake.plugins import DURING, PluginError

GRIPPER_MAX = 0.08  # m between the fingers, fully open
EE_STEP = np.array([0.05, 0.05, 0.05, 0.25, 0.25, 0.25])  # bounds of one ee_delta step

ACTION_SPACES = ("joint_position", "ee_delta", "joint_chunk")


@dataclass
class Counts:
    """What the conversion had to do: clipped actions, unreachable ee targets."""

    steps: int = 0
    clipped: int = 0
    unreachable: int = 0


def check_space(name: str, options: dict) -> None:
    """Refuse an unknown space or bad options before anything runs."""
    if name not in ACTION_SPACES:
        raise InputError(
            f"reference.action_space {name!r}; choose one of: {', '.join(ACTION_SPACES)}"
        )
    if name == "joint_chunk":
        horizon = options.get("horizon", 10)
        execute = options.get("execute", horizon)
        if not (horizon >= 1 and 1 <= execute <= horizon and float(execute).is_integer()):
            raise InputError(
                f"joint_chunk options horizon {horizon:g}, execute {execute:g}: "
                "1 <= execute <= horizon, whole numbers"
            )


def shape(name: str, options: dict) -> tuple[int, ...]:
    """The shape of one action in space ``name``."""
    if name == "joint_position":
        return (8,)
    if name == "ee_delta":
        return (7,)
    return (int(options.get("horizon", 10)), 8)


def bounds(name: str, options: dict, lower, upper) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) of an action, for clipping and for Gymnasium's ``Box``."""
    if name == "ee_delta":
        return np.r_[-EE_STEP, 0.0], np.r_[EE_STEP, 1.0]
    low, high = np.r_[lower, 0.0], np.r_[upper, GRIPPER_MAX]
    if name == "joint_chunk":
        rows = shape(name, options)[0]
        return np.tile(low, (rows, 1)), np.tile(high, (rows, 1))
    return low, high


def checked(action, name: str, options: dict, label: str, lower, upper, counts: Counts):
    """The action as a float array of the space's shape, clipped to its bounds (counted);
    one line naming the policy when it is not an array of that shape of finite numbers."""
    want = shape(name, options)
    try:
        a = np.asarray(action, dtype=float)
    except (TypeError, ValueError):
        raise PluginError(
            f"{label} returned {type(action).__name__} {action!r:.60}; a {name} action is "
            f"an array of shape {want}",
            DURING,
        ) from None
    if a.shape != want:
        raise PluginError(
            f"{label} returned an action of shape {a.shape}; a {name} action has shape {want}",
            DURING,
        )
    if not np.all(np.isfinite(a)):
        raise PluginError(f"{label} returned a non-finite {name} action", DURING)
    low, high = bounds(name, options, lower, upper)
    clipped = np.clip(a, low, high)
    if not np.array_equal(clipped, a):
        counts.clipped += 1
    return clipped


def ee_target(
    delta: np.ndarray, X_WG: RigidTransform, ik, q_seed: np.ndarray, counts: Counts
) -> np.ndarray | None:
    """Joint targets putting the grasp frame at ``X_WG`` moved by ``delta`` (6 numbers), or
    None when the IK cannot reach it (counted)."""
    R = RollPitchYaw(delta[3:6]).ToRotationMatrix().multiply(X_WG.rotation())
    target = RigidTransform(R, X_WG.translation() + delta[:3])
    q = ik.solve(target, q_seed)
    if q is None:
        counts.unreachable += 1
    return q
