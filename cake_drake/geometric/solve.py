"""The exercise's ``solve_action(action, world)``: waypoints -> IK -> joint trajectory."""

from __future__ import annotations

import time

import numpy as np

from cake_drake.errors import IkError
from cake_drake.geometric.ik import IkSolver
from cake_drake.geometric.trajectory import (
    GRIPPER_CLOSED,
    GRIPPER_OPEN,
    JointTrajectory,
    Timing,
)
from cake_drake.geometric.waypoints import WaypointParams, WorldView, waypoints_for
from cake_drake.symbolic import GroundAction


def solve_action(
    action: GroundAction,
    index: int,
    world: WorldView,
    ik: IkSolver,
    trajectory: JointTrajectory,
    timing: Timing = Timing(),
    params: WaypointParams = WaypointParams(),
) -> list[np.ndarray]:
    """Append ``action``'s motion to ``trajectory``; return the IK solution of each waypoint.

    Every waypoint's IK is seeded from the previous solution, so consecutive poses stay
    on one branch of the arm's kinematics. Raises :class:`IkError` naming the action,
    the phase and the pose when a waypoint has no solution.
    """
    solutions = []
    q_seed = trajectory.end_q
    for wp in waypoints_for(action, world, params):
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
    return solutions


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
