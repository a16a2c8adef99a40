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

A learned skill (the geometric layer learned: one ground action at a time, under the
planner) reads ``observation.state`` and ``observation.skill``: the action it executes
and its argument cubes, relative to the hand, so that it does not depend on how many
cubes the problem has or where in the list a cube is (:func:`skill_vector`). The
action's targets are fixed when it starts (:func:`skill_context`), as the classical
layer's waypoints are:

========= ======================================================================
numbers   ``observation.skill`` (float32, 13)
========= ======================================================================
0-3       the action's schema, one-hot: pick-up, unstack, put-down, stack
4-6       the moved cube's centre minus the grasp frame's origin (m, world axes)
7         the moved cube's yaw minus the hand's, modulo 90 degrees (rad, +-pi/4)
8-10      the target minus the grasp frame's origin (m): above the cube at the
          transit height (pick-up, unstack); where the cube's centre is to rest
          (put-down: the table slot; stack: on the lower cube's measured top)
11        the target's yaw minus the hand's, modulo 90 degrees (0 for a pick)
12        the transit height minus the grasp frame's height (m)
========= ======================================================================

A skill that never sees the arm reads ``observation.relative`` instead of
``observation.state`` (:func:`relative_vector`): nothing of the arm's joints and no
absolute height, so the same action in a scene moved up by whole cubes, or across the
table, reads the same numbers:

========= ======================================================================
numbers   ``observation.relative`` (float32, 14)
========= ======================================================================
0-12      ``observation.skill``, as above
13        the gripper's measured width (m)
========= ======================================================================

No clock: a skill that read the time since its action began would take a slower
approach than its demonstrator's for a later phase (closing the hand above a cube it
has not reached yet); where the hand is from the cube and the target, and the gripper's
width, say which phase it is in.

``ground_action`` (int64, 4) says per frame which ground action it is: the schema's
index (-1: none under way), the cubes' indices in ``cubes`` (-1: none), and the action's
place in the plan; a recording is cut into per-action segments where it changes.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform

from cake_drake.geometric.waypoints import (
    WaypointParams,
    face_yaw,
    free_slot,
    transit_height,
    yaw_of,
)
from cake_drake.symbolic import fact_str
from cake_drake.world.scene import CUBE_SIZE

#: The most cubes an observation describes (the project's largest Blocksworld).
MAX_CUBES = 12
#: Columns of a cube's goal row: the 12 cubes, then the table.
GOAL_COLUMNS = MAX_CUBES + 1
ENVIRONMENT_STATE_SIZE = MAX_CUBES * 7 + MAX_CUBES * GOAL_COLUMNS
#: Where the goal's numbers start in ``observation.environment_state`` (the poses before).
GOAL_START = MAX_CUBES * 7


#: The ground actions a skill executes, by what they do (the exercise's names).
SKILL_SCHEMAS = ("pick-up", "unstack", "put-down", "stack")
SKILL_SIZE = 13
#: ``observation.relative``: the skill's numbers and the gripper's width.
RELATIVE_SIZE = SKILL_SIZE + 1
#: The frame's ground action: schema, moved cube, other cube, the action's place in the plan.
GROUND_ACTION_SIZE = 4
NO_GROUND_ACTION = np.full(GROUND_ACTION_SIZE, -1, np.int64)


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


@dataclass(frozen=True)
class SkillContext:
    """What a skill is told when its ground action starts (fixed until it ends): the
    schema, the moved cube, the other cube (or None), the place target (the cube's
    centre at rest, or None for a pick), its yaw, and the transit height."""

    schema: str  # one of SKILL_SCHEMAS
    cube: str
    other: str | None
    target: np.ndarray | None
    target_yaw: float
    z_transit: float


def _quarter(angle: float) -> float:
    """``angle`` modulo 90 degrees, in [-pi/4, pi/4)."""
    return float((angle + np.pi / 4) % (np.pi / 2) - np.pi / 4)


def skill_context(action, cubes: Mapping[str, RigidTransform], slots, params=None) -> SkillContext:
    """The targets of ``action`` (in the exercise's names, see ``SKILL_SCHEMAS``) from the
    world measured as it starts: the classical layer's own (its free slot, the lower
    cube's top, its transit height: :mod:`cake_drake.geometric.waypoints`)."""
    params = params or WaypointParams()
    name, args = action.name, tuple(action.args)
    if name not in SKILL_SCHEMAS:
        raise ValueError(f"{action}: a skill executes {', '.join(SKILL_SCHEMAS)}")
    cube = args[0]
    other = args[1] if len(args) > 1 else None
    target, target_yaw = None, 0.0
    if name == "stack":
        X = cubes[other]
        target = X.translation() + [0.0, 0.0, CUBE_SIZE]
        target_yaw = face_yaw(X)
    elif name == "put-down":
        x, y = free_slot(cubes, cube, params, slots)
        target = np.array([x, y, CUBE_SIZE / 2])
        target_yaw = float(np.arctan2(y, x))
    held = cube if name in ("put-down", "stack") else None
    return SkillContext(name, cube, other, target, target_yaw,
                        transit_height(cubes, held, params))  # fmt: skip


def skill_vector(
    context: SkillContext, cubes: Mapping[str, RigidTransform], X_WG: RigidTransform
) -> np.ndarray:
    """``observation.skill`` (see the module's table) from the measured poses now."""
    p_G = X_WG.translation()
    hand_yaw = yaw_of(X_WG)
    X_cube = cubes[context.cube]
    out = np.zeros(SKILL_SIZE, np.float32)
    out[SKILL_SCHEMAS.index(context.schema)] = 1.0
    out[4:7] = X_cube.translation() - p_G
    out[7] = _quarter(face_yaw(X_cube) - hand_yaw)
    if context.target is None:  # a pick: up above the cube, at the transit height
        target = np.array([*X_cube.translation()[:2], context.z_transit])
        out[11] = 0.0
    else:
        target = context.target
        if context.schema == "stack":  # the lower cube as measured now
            target = cubes[context.other].translation() + [0.0, 0.0, CUBE_SIZE]
        out[11] = _quarter(context.target_yaw - hand_yaw)
    out[8:11] = target - p_G
    out[12] = context.z_transit - p_G[2]
    return out


def relative_vector(skill: np.ndarray, width: float) -> np.ndarray:
    """``observation.relative`` (see the module's table): ``skill`` (:func:`skill_vector`)
    and the gripper's measured ``width`` (m)."""
    out = np.empty(RELATIVE_SIZE, np.float32)
    out[:SKILL_SIZE] = skill
    out[SKILL_SIZE] = width
    return out


def ground_row(context: SkillContext | None, cubes: Sequence[str], position: int) -> np.ndarray:
    """``ground_action`` (see the module's table) for ``context`` (None: no action)."""
    if context is None:
        return NO_GROUND_ACTION.copy()
    index = {c: k for k, c in enumerate(cubes)}
    return np.array([
        SKILL_SCHEMAS.index(context.schema), index[context.cube],
        index.get(context.other, -1) if context.other else -1, position,
    ], np.int64)  # fmt: skip
