"""Read simulated cube poses back as Blocksworld facts: the bridge every check uses.

A cube is *on the table* when its centre is half a cube above the table top, *on*
another cube when its centre is one cube above that cube's centre and within half a
cube of it horizontally, and *clear* when no cube is on it. A cube that is tilted more
than :data:`TILT_TOL` rests on neither and is reported.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform

from cake_drake.world.scene import CUBE_SIZE

HEIGHT_TOL = 0.006  # m: how far a resting cube's centre may be from its nominal height
STACK_TOL = 0.005  # m: a goal's stacked cube must stand within this of the one below (xy)
#: m: a stacked cube farther than this off the one below is set down again by the closed-loop
#: expert (:mod:`cake_drake.learning.policies.expert`), and is not let go by a learned skill
#: (:meth:`cake_drake.systems.skills.LearnedSkills._gripper`): within the verdict's tolerance.
CENTRED = 0.8 * STACK_TOL
TILT_TOL = 0.1  # rad: a cube tilted more than this does not rest flat


@dataclass(frozen=True)
class Reading:
    """Facts read from poses, plus what could not be classified."""

    facts: frozenset[tuple[str, ...]]
    problems: tuple[str, ...]


def tilt(X: RigidTransform) -> float:
    """Angle between the cube's nearest face normal and world z (cubes are symmetric)."""
    R = X.rotation().matrix()
    return float(np.arccos(np.clip(np.max(np.abs(R[2, :])), -1.0, 1.0)))


#: A cube whose centre is this close to the grasp frame, between closed fingers, is held.
HELD_TOL = 0.025  # m (a cube may sit off-centre between the pads)
#: Finger opening (each finger, m) that says the fingers are closed on a 4 cm cube.
GRIP_RANGE = (0.012, 0.026)


def held_cube(
    poses: Mapping[str, RigidTransform],
    X_WG: RigidTransform | None,
    finger_opening: float | None,
) -> str | None:
    """The cube in the hand, measured: its centre at the grasp frame, the fingers on it."""
    if X_WG is None or finger_opening is None:
        return None
    if not GRIP_RANGE[0] <= finger_opening <= GRIP_RANGE[1]:
        return None
    p = X_WG.translation()
    near = [n for n, X in sorted(poses.items()) if np.linalg.norm(X.translation() - p) < HELD_TOL]
    return near[0] if len(near) == 1 else None


def read_facts(
    poses: Mapping[str, RigidTransform],
    size: float = CUBE_SIZE,
    X_WG: RigidTransform | None = None,
    finger_opening: float | None = None,
) -> Reading:
    """Facts ``on``, ``on-table`` and ``clear`` for cubes at ``poses`` (world frame).

    With the grasp frame's pose ``X_WG`` and the fingers' opening, the arm's state is read
    too: ``(holding x)`` for the cube between the closed fingers, else ``(arm-empty)``.
    """
    facts: set[tuple[str, ...]] = set()
    problems: list[str] = []
    held = held_cube(poses, X_WG, finger_opening)
    if X_WG is not None:
        facts.add(("holding", held) if held else ("arm-empty",))
        if held:
            poses = {n: X for n, X in poses.items() if n != held}
    supported: set[str] = set()
    covered: set[str] = set()
    for name, X in sorted(poses.items()):
        p = X.translation()
        if tilt(X) > TILT_TOL:
            problems.append(f"{name} is tilted by {np.degrees(tilt(X)):.0f} deg")
            continue
        if abs(p[2] - size / 2) < HEIGHT_TOL:
            facts.add(("on-table", name))
            supported.add(name)
            continue
        below = [
            other
            for other, Y in sorted(poses.items())
            if other != name
            and abs(p[2] - Y.translation()[2] - size) < HEIGHT_TOL
            and np.linalg.norm(p[:2] - Y.translation()[:2]) < size / 2
        ]
        if below:
            facts.add(("on", name, below[0]))
            supported.add(name)
            covered.add(below[0])
        else:
            problems.append(f"{name} rests on nothing (centre at z = {p[2] * 1000:.1f} mm)")
    for name in sorted(poses):
        if name in supported and name not in covered:
            facts.add(("clear", name))
    return Reading(frozenset(facts), tuple(problems))


def stack_offsets(poses: Mapping[str, RigidTransform], facts) -> dict[str, float]:
    """Horizontal offset (m) of every stacked cube from the cube it stands on."""
    return {
        f[1]: float(np.linalg.norm(poses[f[1]].translation()[:2] - poses[f[2]].translation()[:2]))
        for f in facts
        if f[0] == "on"
    }


@dataclass(frozen=True)
class GoalReading:
    """The goal as the measured world shows it, read one way for everyone (the run's
    verdict, the policy slot, the Gym env, the expert): the goal facts that hold and the
    ones missing (a cube still in the hand stands on nothing), each goal-stacked cube
    farther than :data:`STACK_TOL` off the one below, and whether a cube left the table."""

    true: frozenset
    missing: frozenset
    loose: dict  # cube -> its xy offset (m) from the cube below, where over STACK_TOL
    lost: bool

    @property
    def reached(self) -> bool:
        return not self.missing and not self.loose

    def reward(self, goal: frozenset) -> float:
        return len(self.true) / len(goal) if goal else 1.0


def read_goal(
    poses: Mapping[str, RigidTransform],
    goal: frozenset,
    X_WG: RigidTransform | None = None,
    finger_opening: float | None = None,
    reading: Reading | None = None,
) -> GoalReading:
    """:class:`GoalReading` of ``goal`` (canonical facts) from the cubes' poses, the grasp
    frame and a finger's opening (or a :func:`read_facts` ``reading`` of them)."""
    if reading is None:
        reading = read_facts(poses, X_WG=X_WG, finger_opening=finger_opening)
    true = frozenset(goal & reading.facts)
    offsets = stack_offsets(poses, reading.facts)
    loose = {
        f[1]: offsets[f[1]]
        for f in sorted(true)
        if f[0] == "on" and offsets.get(f[1], 0.0) > STACK_TOL
    }
    lost = any(X.translation()[2] < -0.05 for X in poses.values())
    return GoalReading(true, frozenset(goal - true), loose, lost)


#: m from the arm's base beyond which a cube is out of reach (no plan can use it).
TABLE_REACH = 0.85


def lost_cubes(cubes: Mapping[str, RigidTransform]) -> list[str]:
    """Cubes no plan can use, each as a line: off the table, or out of the arm's reach."""
    return [
        f"{n} fell off the table (at {np.round(X.translation(), 2).tolist()} m)"
        for n, X in sorted(cubes.items())
        if X.translation()[2] < -0.01
    ] + [
        f"{n} is out of the arm's reach ({np.hypot(*X.translation()[:2]):.2f} m from its base)"
        for n, X in sorted(cubes.items())
        if np.hypot(*X.translation()[:2]) > TABLE_REACH
    ]
