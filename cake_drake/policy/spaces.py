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
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from cake_drake.errors import InputError
from cake_drake.geometric.waypoints import yaw_of
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


#: The most rows a ``joint_chunk`` action may have (100 control periods: 10 s at 10 Hz).
MAX_HORIZON = 100


def _whole(value, name: str, lo: int, hi: int, where: str) -> int:
    """``value`` as a whole number in ``lo``..``hi``; one line naming ``where`` otherwise."""
    number = isinstance(value, int | float) and not isinstance(value, bool)
    if not (number and float(value).is_integer() and lo <= value <= hi):
        shown = f"{value:g}" if number else repr(value)
        shown = shown if len(shown) <= 24 else shown[:20] + "..."
        raise InputError(
            f"{where}.{name} = {shown}: a whole number of control periods from {lo} to {hi} "
            "(1 <= execute <= horizon)"
        )
    return int(value)


def check_space(name: str, options: dict, where: str = "reference.options") -> None:
    """Refuse an unknown space or bad options before anything runs: a ``joint_chunk``'s
    ``horizon`` and ``execute`` are whole numbers, 1 <= execute <= horizon <= MAX_HORIZON."""
    if name not in ACTION_SPACES:
        raise InputError(
            f"reference.action_space {name!r}; choose one of: {', '.join(ACTION_SPACES)}"
        )
    if name == "joint_chunk":
        horizon = _whole(options.get("horizon", 10), "horizon", 1, MAX_HORIZON, where)
        _whole(options.get("execute", horizon), "execute", 1, horizon, where)


def periods(name: str, options: dict) -> int:
    """Control periods one action is held for: a chunk's ``execute`` rows, otherwise 1."""
    if name != "joint_chunk":
        return 1
    return int(options.get("execute", options.get("horizon", 10)))


#: A step budget of 0 is scaled to the task: this much simulated time per planned action,
#: plus a fixed allowance (s). At 10 Hz a 12-block problem's ~30 actions get 260 s.
BUDGET_PER_ACTION_S = 8.0
BUDGET_BASE_S = 20.0


def step_budget(max_steps: int, n_actions: int, rate_hz: float, periods: int = 1) -> int:
    """The policy's step budget: ``max_steps``, or (0) scaled to the classical plan's
    length, ``BUDGET_BASE_S + BUDGET_PER_ACTION_S`` per action, in steps at ``rate_hz``."""
    if max_steps:
        return int(max_steps)
    seconds = BUDGET_BASE_S + BUDGET_PER_ACTION_S * max(n_actions, 1)
    return max(1, int(np.ceil(seconds * rate_hz / periods)))


def budget_text(max_steps: int, rate_hz: float, periods: int = 1) -> str:
    """How a step budget that ran out is named: its steps and its simulated seconds."""
    seconds = max_steps * periods / rate_hz
    return f"the policy's step budget of {max_steps} ({seconds:.1f} s) ran out"


def read_answer(answer, label: str) -> tuple[object, bool]:
    """A policy's answer to ``act`` as (action, done): an action, ``(action, done)`` or
    ``(None, True)``; ``done`` a bool. Anything else is one line naming the policy."""
    if not isinstance(answer, tuple):
        return answer, False
    if len(answer) != 2:
        raise PluginError(
            f"{label} returned a tuple of {len(answer)}; act() returns an action, or "
            "(action, done) with done a bool",
            DURING,
        )
    action, done = answer
    if not isinstance(done, bool | np.bool_):
        raise PluginError(
            f"{label} returned done = {done!r:.40} ({type(done).__name__}); done is a bool "
            "(True: the policy is finished)",
            DURING,
        )
    if action is None and not done:
        raise PluginError(f"{label} returned (None, False): no action and not done", DURING)
    return action, bool(done)


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


def checked(action, name: str, options: dict, label: str, lower, upper, counts: Counts, box=None):
    """The action as a float array of the space's shape, clipped to its bounds (counted);
    one line naming the policy when it is not an array of that shape of finite numbers.
    ``box``: the space's (low, high), when the caller keeps them (:func:`bounds`)."""
    want = shape(name, options)
    try:
        if isinstance(action, dict | str | bytes) or action is None:
            raise TypeError
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
    low, high = box if box is not None else bounds(name, options, lower, upper)
    clipped = np.clip(a, low, high)
    if not np.array_equal(clipped, a):
        counts.clipped += 1
    return clipped


def ee_target(
    delta: np.ndarray,
    X_WG: RigidTransform,
    ik,
    q_seed: np.ndarray,
    counts: Counts,
    down: bool = False,
) -> np.ndarray | None:
    """Joint targets putting the grasp frame at ``X_WG`` moved by ``delta`` (6 numbers), or
    None when the IK cannot reach it (counted). ``down``: the hand pointing straight down,
    turned by its measured yaw plus ``delta``'s dyaw (droll and dpitch unused): a top-down
    hand whose tilt cannot drift from step to step."""
    if down:
        yaw = yaw_of(X_WG) + float(delta[5])
        R = RotationMatrix.MakeZRotation(yaw).multiply(RotationMatrix.MakeXRotation(np.pi))
    else:
        R = RollPitchYaw(delta[3:6]).ToRotationMatrix().multiply(X_WG.rotation())
    target = RigidTransform(R, X_WG.translation() + delta[:3])
    q = ik.solve(target, q_seed)
    if q is None:
        counts.unreachable += 1
    return q
