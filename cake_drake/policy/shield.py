"""The shield around a learned skill: small named steps between the world and the network.

A step changes what the skill reads (``observation``), what it answered (``action``), or
ends a try (``end``); :class:`~cake_drake.systems.skills.LearnedSkills` runs the steps
``motion.skill_rules`` names, in that order within their phase, and counts how often each
changed the network's answer. ``[]`` is the network alone. Each step does what the
classical layer does by construction (it goes down only over the cube, crosses at the
transit height, closes only at the grasp); why each was added, and what it bought, is
the record in docs/learning_studies.md ("The shield's steps").

The bounds of the ``ee_delta`` action space (its box) and the damped least squares below
the answer are not steps: every policy of that space gets them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from pydrake.math import RigidTransform

from cake_drake.geometric.waypoints import (
    WaypointParams,
    around_base,
    comfortable_yaw,
    nearest_turn,
    transit_height,
    yaw_of,
)
from cake_drake.policy import spaces
from cake_drake.policy.observations import SkillContext
from cake_drake.world.facts import CENTRED
from cake_drake.world.scene import CUBE_SIZE

#: m: the gripper's widest opening.
GRIPPER_MAX = 0.08
#: m/s each finger's command moves at most (the classical layer's close and open:
#: ``Timing.gripper_time`` in :mod:`cake_drake.geometric.trajectory`, 4 cm in 0.2 s).
FINGER_SPEED = 0.2
#: m: a destination further across from the hand than this is far: it is read on the way
#: around the arm's base, and crossed to at the transit height.
FAR_ACROSS = 0.15
#: m: a hand that moved less than this in a control period has stopped.
STOPPED_M = 0.001
#: s: a hand stopped this long with its action not done ends its try.
STILL_END_S = 2.0
#: s: a place's hand stopped this long where its cube rests on its target lets it go.
STILL_LET_GO_S = 1.0
#: m: a stopped hand's move is taken from where it was last sent, at most this far on.
CATCH_UP_M = 0.02
#: m: a hand this close across to where it goes down to is over it.
OVER_M = 0.01
#: m: a cube this close across to the hand's way is beside it (the open fingers'
#: half-span, a finger's width and a cube's half-diagonal).
BESIDE_WAY_M = 0.08
#: m: a place's cube this close above its rest counts as resting there.
RESTING_M = 0.01
#: m: fingers this much wider than a cube have let go of it.
LET_GO_MARGIN_M = 0.004


@dataclass(frozen=True)
class Period:
    """What a step reads in one control period: the action under way, the measured
    world, and what the skill system remembers of the periods before."""

    action: SkillContext
    cubes: dict
    X_WG: RigidTransform  # the grasp frame, measured
    width: float  # m: the gripper's measured opening
    params: WaypointParams
    period_s: float = 0.1  # s: the control period
    fingers: float = 0.0  # m: the gripper's present command
    sent: np.ndarray | None = None  # x y z where the hand was last sent
    still_s: float = 0.0  # s the hand has stood still
    wrist: float | None = None  # rad: the yaw kept through the action (None: not chosen)
    max_turn: float = 0.0  # rad the hand may turn in a period
    free_turns: bool = False  # the skill reads yaws modulo a quarter turn


@dataclass(frozen=True)
class Answer:
    """What the network answered, as the action steps change it: a move of the hand
    (dx dy dz droll dpitch dyaw) from ``base``, the gripper's width, the yaw kept."""

    move: np.ndarray
    width: float
    base: RigidTransform
    wrist: float | None = None

    def same_as(self, other: Answer) -> bool:
        return (
            np.array_equal(self.move, other.move)
            and self.width == other.width
            and np.array_equal(self.base.translation(), other.base.translation())
        )


@dataclass(frozen=True)
class Step:
    """A named step: its phase (``end``, ``observation`` or ``action``), the action spaces
    it runs for, and the function."""

    name: str
    phase: str
    spaces: tuple[str, ...]
    run: Callable

    @property
    def doc(self) -> str:
        """The function's docstring, in one line."""
        return " ".join((self.run.__doc__ or "").split())


def _down_to(period: Period) -> np.ndarray:
    """Where the hand goes down to: a pick's cube, or where the hand is when a place's
    cube rests on its target."""
    cube = period.cubes[period.action.cube].translation()
    hand = period.X_WG.translation()
    return cube if period.action.target is None else period.action.target + (hand - cube)


# --- end: a try ended before its budget ----------------------------------------------


def end_try_when_still(p: Period) -> bool:
    """A hand stopped ``STILL_END_S`` with its action not done ends its try."""
    return p.still_s >= STILL_END_S


# --- observation: what the network reads ----------------------------------------------


def route_around_base(p: Period, skill: np.ndarray) -> np.ndarray:
    """A destination further than ``FAR_ACROSS`` reads as the point that far on the way
    around the arm's base."""
    hand = p.X_WG.translation()[:2]
    picking = p.action.target is None  # the hand goes to the cube; a place's, to its target
    destination = hand + (skill[4:6] if picking else skill[8:10])
    shift = around_base(hand, destination, FAR_ACROSS) - destination
    if not shift.any():
        return skill
    out = skill.copy()
    out[8:10] += shift
    if picking:
        out[4:6] += shift
    return out


def retract_clear_of_placed(p: Period, skill: np.ndarray) -> np.ndarray:
    """Once a place has let go, the transit height reads as the retract's, clear of the
    cube just placed."""
    if p.action.target is None or p.width <= CUBE_SIZE + LET_GO_MARGIN_M:
        return skill
    cube = p.cubes[p.action.cube].translation()
    after = cube[2] + CUBE_SIZE + p.params.transit_clearance - p.X_WG.translation()[2]
    if after <= skill[12]:
        return skill
    out = skill.copy()
    out[12] = after
    return out


# --- action: what the network answered ------------------------------------------------


def keep_wrist_mid_range(p: Period, a: Answer) -> Answer:
    """The hand turns to the quarter turn of the answer nearest the comfortable yaw,
    chosen once an action."""
    if not p.free_turns:
        return a
    hand = yaw_of(p.X_WG)
    dyaw, wrist = float(a.move[5]), a.wrist
    if wrist is None:
        action = p.action
        where = action.target if action.target is not None else p.cubes[action.cube].translation()
        wrist = nearest_turn(hand + dyaw, comfortable_yaw(where, p.params))
    goal = nearest_turn(hand + dyaw, wrist)
    move = a.move.copy()
    move[5] = float(np.clip(goal - hand, -p.max_turn, p.max_turn))
    return replace(a, move=move, wrist=wrist)


def move_from_where_sent(p: Period, a: Answer) -> Answer:
    """A stopped hand's move is taken from where it was last sent (at most
    ``CATCH_UP_M`` on), so a steady shortfall adds up until the hand moves."""
    if p.still_s <= 0.0:
        return a
    X_WG = p.X_WG
    short = np.asarray(p.sent, float) - X_WG.translation()
    far = float(np.linalg.norm(short))
    if far > CATCH_UP_M:
        short *= CATCH_UP_M / far
    return replace(a, base=RigidTransform(X_WG.rotation(), X_WG.translation() + short))


def _across_to(p: Period) -> tuple[float, float]:
    """How far across the hand is from where it goes down to, and how close counts as
    over it (half a cube for a put-down's free spot, ``OVER_M`` otherwise)."""
    hand = p.X_WG.translation()
    across = float(np.hypot(*(_down_to(p)[:2] - hand[:2])))
    putting_down = p.action.target is not None and p.action.other is None
    return across, (CUBE_SIZE / 2 if putting_down else OVER_M)


def cross_at_transit_height(p: Period, a: Answer) -> Answer:
    """Further than ``FAR_ACROSS`` across, the hand keeps to the transit height, rising
    to it at most a step a period."""
    across, _ = _across_to(p)
    if across <= FAR_ACROSS:
        return a
    z = a.base.translation()[2]
    held = p.action.cube if p.action.target is not None else None
    rise = min(transit_height(p.cubes, held, p.params) - z, spaces.EE_STEP[2])
    move = a.move.copy()
    move[2] = max(float(a.move[2]), rise)
    return replace(a, move=move)


def descend_only_over_target(p: Period, a: Answer) -> Answer:
    """Not yet over where it goes down to, the hand keeps the pre-grasp height above it
    and above every cube beside its way."""
    across, over = _across_to(p)
    if across <= over or across > FAR_ACROSS:
        return a
    action, hand, z = p.action, p.X_WG.translation(), a.base.translation()[2]
    start, end = hand[:2], a.base.translation()[:2] + np.asarray(a.move[:2], float)
    floor = _down_to(p)[2]
    for name, X in p.cubes.items():
        at = X.translation()
        if name != action.cube and _across(at[:2], start, end) <= BESIDE_WAY_M:
            floor = max(floor, at[2])
    held_at = z if p.sent is None else max(z, float(p.sent[2]))  # no lower than sent
    lowest = min(held_at, floor + p.params.approach)
    move = a.move.copy()
    move[2] = max(float(a.move[2]), lowest - z)
    return replace(a, move=move)


def _cube_out(p: Period) -> bool:
    """The action's cube is out of the fingers (its centre further than ``RESTING_M`` and
    half a cube from the grasp frame)."""
    cube, hand = p.cubes[p.action.cube].translation(), p.X_WG.translation()
    return bool(np.linalg.norm(cube - hand) > RESTING_M + CUBE_SIZE / 2)


def _rests(p: Period) -> bool:
    """A place's cube rests on its target: within ``CENTRED`` across of it for a stack
    (half a cube for a put-down) and no more than ``RESTING_M`` above it."""
    off = p.cubes[p.action.cube].translation() - p.action.target
    across = CUBE_SIZE / 2 if p.action.other is None else CENTRED
    return bool(np.hypot(*off[:2]) <= across and off[2] <= RESTING_M)


def open_while_away(p: Period, a: Answer) -> Answer:
    """A pick's fingers are open while its cube is out of them."""
    if p.action.target is None and _cube_out(p):
        return replace(a, width=GRIPPER_MAX)
    return a


def close_only_around_cube(p: Period, a: Answer) -> Answer:
    """A pick's fingers close only with its cube between them."""
    if p.action.target is not None or _cube_out(p) or a.width >= p.fingers:
        return a
    off = p.cubes[p.action.cube].translation() - p.X_WG.translation()
    around = np.hypot(*off[:2]) <= CUBE_SIZE / 2 and abs(off[2]) <= CUBE_SIZE / 2
    return a if around else replace(a, width=p.fingers)


def stay_open_after_release(p: Period, a: Answer) -> Answer:
    """A place's fingers, once its cube is out of them, close no further."""
    if p.action.target is not None and _cube_out(p) and a.width < p.fingers:
        return replace(a, width=p.fingers)
    return a


def open_only_where_resting(p: Period, a: Answer) -> Answer:
    """A place's fingers open only with its cube resting on its target."""
    if p.action.target is None or _cube_out(p) or a.width <= p.fingers or _rests(p):
        return a
    return replace(a, width=p.fingers)


def let_go_when_resting_still(p: Period, a: Answer) -> Answer:
    """A place's hand stopped ``STILL_LET_GO_S`` with its cube resting on its target
    lets go."""
    if p.action.target is None or _cube_out(p) or p.still_s < STILL_LET_GO_S:
        return a
    return replace(a, width=GRIPPER_MAX) if _rests(p) else a


def limit_finger_speed(p: Period, a: Answer) -> Answer:
    """The fingers' command moves at most ``FINGER_SPEED``, as every demonstrator's."""
    was, most = p.fingers / 2, FINGER_SPEED * p.period_s
    return replace(a, width=2 * float(np.clip(a.width / 2, was - most, was + most)))


def _across(point, a, b) -> float:
    """How far (m) ``point`` is from the segment ``a``-``b`` (x y)."""
    ab = b - a
    t = float(np.clip(np.dot(point - a, ab) / max(float(np.dot(ab, ab)), 1e-12), 0.0, 1.0))
    return float(np.hypot(*(point - (a + t * ab))))


_HAND = ("ee_delta",)
_ANY = ("ee_delta", "joint_position")
#: Every step, in the order the shipped skills run them.
STEPS: dict[str, Step] = {
    s.name: s
    for s in (
        Step("end_try_when_still", "end", _HAND, end_try_when_still),
        Step("route_around_base", "observation", _HAND, route_around_base),
        Step("retract_clear_of_placed", "observation", _HAND, retract_clear_of_placed),
        Step("keep_wrist_mid_range", "action", _HAND, keep_wrist_mid_range),
        Step("move_from_where_sent", "action", _HAND, move_from_where_sent),
        Step("cross_at_transit_height", "action", _HAND, cross_at_transit_height),
        Step("descend_only_over_target", "action", _HAND, descend_only_over_target),
        Step("open_while_away", "action", _HAND, open_while_away),
        Step("close_only_around_cube", "action", _HAND, close_only_around_cube),
        Step("stay_open_after_release", "action", _HAND, stay_open_after_release),
        Step("open_only_where_resting", "action", _HAND, open_only_where_resting),
        Step("let_go_when_resting_still", "action", _HAND, let_go_when_resting_still),
        Step("limit_finger_speed", "action", _ANY, limit_finger_speed),
    )
}
#: ``motion.skill_rules``' default: every step, as the shipped figures were measured.
DEFAULT = tuple(STEPS)


def check_names(names, where: str = "motion.skill_rules") -> tuple[str, ...]:
    """The step names of ``names``, each known and named once; a ``ValueError`` naming
    the first that is not, and the valid names, otherwise."""
    if isinstance(names, str) or not all(isinstance(n, str) for n in names):
        raise ValueError(f"{where}: a list of step names; the steps are {', '.join(STEPS)}")
    seen = set()
    for name in names:
        if name not in STEPS:
            raise ValueError(f"{where}: no step {name!r}; the steps are {', '.join(STEPS)}")
        if name in seen:
            raise ValueError(f"{where}: {name!r} named twice; each step runs once")
        seen.add(name)
    return tuple(names)
