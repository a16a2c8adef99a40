"""The exercise's ``solve_action(action, world)``: waypoints -> IK -> joint trajectory."""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from cake_drake.errors import IkError
from cake_drake.geometric.collisions import Collision, CollisionChecker, action_collisions
from cake_drake.geometric.ik import IkSolver
from cake_drake.geometric.trajectory import (
    GRIPPER_CLOSED,
    GRIPPER_OPEN,
    JointTrajectory,
    Timing,
)
from cake_drake.geometric.waypoints import Waypoint, WaypointParams, WorldView, waypoints_for
from cake_drake.symbolic import GroundAction


@dataclass(frozen=True)
class Motion:
    """What :func:`solve_action` planned for one action."""

    waypoints: tuple[Waypoint, ...]
    solutions: tuple[np.ndarray, ...]  # IK solution of each waypoint
    collisions: tuple[tuple[str, Collision], ...] = ()  # (phase, collision), if checked
    transit_clearance: float = 0.0  # the clearance the motion was planned with (m)

    def warnings(self, index: int, action: GroundAction) -> list[str]:
        """One line per collision, naming the action and the phase."""
        return [f"action {index + 1} {action}, {phase}: {c}" for phase, c in self.collisions]


#: What --avoid-collisions tries, in order, until a motion hits nothing: the transit
#: height raised by these amounts (m), each with the gripper at its comfortable yaw and
#: turned a quarter (the hand is wide along its fingers).
AVOID_RAISES = (0.0, 0.05, 0.10)
AVOID_TURNS = (0, 1)


def _plan(action, index, world, ik, trajectory, timing, params):
    waypoints = waypoints_for(action, world, params)
    solutions = []
    q_seed = trajectory.end_q
    for wp in waypoints:
        q = ik.solve(wp.X_WG, q_seed)
        if q is None:
            p = np.round(wp.X_WG.translation(), 3).tolist()
            raise IkError(
                f"action {index + 1} {action}: no IK solution ({ik.name}) for the "
                f"{wp.phase} pose at {p} m (gripper pointing down); the cube may be out of reach"
            )
        solutions.append(q)
        trajectory.move(q, wp.phase, index, timing)
        want = GRIPPER_OPEN if wp.gripper == "open" else GRIPPER_CLOSED
        if want != trajectory.end_gripper:
            trajectory.hold(timing.settle_time, wp.phase, index)
            trajectory.hold(timing.gripper_time, wp.phase, index, gripper=want)
        q_seed = q
    return tuple(waypoints), tuple(solutions)


def solve_action(
    action: GroundAction,
    index: int,
    world: WorldView,
    ik: IkSolver,
    trajectory: JointTrajectory,
    timing: Timing = Timing(),
    params: WaypointParams = WaypointParams(),
    checker: CollisionChecker | None = None,
    avoid_collisions: bool = False,
) -> Motion:
    """Append ``action``'s motion to ``trajectory``: waypoints, IK, timed moves.

    Every waypoint's IK is seeded from the previous solution, so consecutive poses stay
    on one branch of the arm's kinematics. Raises :class:`IkError` naming the action,
    the phase and the pose when a waypoint has no solution.

    With a ``checker`` every move is checked for collisions with cubes other than the
    action's own and with the table (the symbolic plan knows no geometry); they are
    returned, to be reported. With ``avoid_collisions`` the motion is planned again,
    with the transit height raised and the gripper turned a quarter
    (:data:`AVOID_RAISES` x :data:`AVOID_TURNS`), until one hits nothing; if none is
    free, the one with the shallowest collisions is kept and its collisions returned.
    """
    start = trajectory.copy()
    variants = [(0.0, 0)]
    if checker is not None and avoid_collisions:
        variants = [(dz, turn) for dz in AVOID_RAISES for turn in AVOID_TURNS]
    best = None
    first_error = None
    for dz, turn in variants:
        p = replace(
            params,
            transit_clearance=params.transit_clearance + dz,
            yaw_turns=params.yaw_turns + turn,
        )
        candidate = start.copy()
        try:
            waypoints, solutions = _plan(action, index, world, ik, candidate, timing, p)
        except IkError as e:  # another variant may still reach: keep the first error
            first_error = first_error or e
            continue
        found = ()
        if checker is not None:
            found = tuple(
                action_collisions(checker, action, world, waypoints, start.end_q, solutions)
            )
        depth = sum(c.depth for _, c in found)
        if best is None or depth < best[0]:
            best = (depth, candidate, Motion(waypoints, solutions, found, p.transit_clearance))
        if not found:
            break
    if best is None:
        raise first_error
    trajectory.assign(best[1])
    return best[2]


class TimedSolver:
    """Wraps an :class:`IkSolver` and records the wall time of every solve (ms)."""

    def __init__(self, solver: IkSolver) -> None:
        self.solver = solver
        self.name = solver.name
        self.times_ms: list[float] = []

    def solve(self, X_WG, q_seed):
        t0 = time.perf_counter()
        try:
            return self.solver.solve(X_WG, q_seed)
        finally:
            self.times_ms.append((time.perf_counter() - t0) * 1000)
