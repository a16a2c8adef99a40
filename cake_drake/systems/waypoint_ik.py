"""``WaypointIk``: the geometric layer inside the Diagram."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem

from cake_drake.errors import ExecutionError
from cake_drake.geometric.collisions import CollisionChecker
from cake_drake.geometric.ik import IkSolver
from cake_drake.geometric.solve import solve_action
from cake_drake.geometric.trajectory import JointTrajectory, Timing
from cake_drake.geometric.waypoints import PICK_ACTIONS, WaypointParams, WorldView
from cake_drake.systems.plan_source import ActionCommand
from cake_drake.world.scene import SLOTS

#: Layout of the ``reference`` output vector.
REFERENCE_SLICES = {
    "q": slice(0, 7),
    "v": slice(7, 14),
    "a": slice(14, 21),
    "fingers": slice(21, 25),  # desired finger state: q1, q2, v1, v2
    "done": slice(25, 26),
    "labels": slice(26, 28),  # phase index, action index
}
REFERENCE_SIZE = 28


@dataclass(frozen=True)
class Progress:
    """Immutable snapshot of execution: Drake's state copies share it instead of copying."""

    trajectory: JointTrajectory
    working: int = -1  # index of the action being executed, -1 when idle
    done: int = 0  # actions finished
    held: str | None = None  # cube in the hand, by the plan
    error: str | None = None
    warnings: tuple[str, ...] = ()  # collisions found along the planned moves

    def __deepcopy__(self, memo):
        return self


class WaypointIk(LeafSystem):
    """Turns each action into a timed joint trajectory, from the *measured* world.

    .. pydrake_system::

        name: WaypointIk
        input_ports:
        - action
        - body_poses
        output_ports:
        - reference

    When ``action`` names an action it has not started, it reads the cube and gripper
    poses from ``body_poses`` (the plant's), computes the waypoints, solves IK and
    appends the moves (:func:`cake_drake.geometric.solve.solve_action`). ``reference``
    is [q_d (7), v_d (7), a_d (7), finger q_d (2), finger v_d (2), actions done,
    phase index, action index]; an action counts as done when its trajectory has run
    out. An IK failure stops execution and is kept in the state (``Progress.error``);
    collisions found along the planned moves (with a ``checker``) are kept as warnings.
    """

    def __init__(
        self,
        ik: IkSolver,
        q_start: np.ndarray,
        cube_bodies: Mapping[str, int],
        hand_body: int,
        X_hand_grasp: RigidTransform,
        period: float,
        timing: Timing = Timing(),
        params: WaypointParams = WaypointParams(),
        slots: tuple[tuple[float, float], ...] = SLOTS,
        checker: CollisionChecker | None = None,
        avoid_collisions: bool = False,
    ) -> None:
        super().__init__()
        self._slots = tuple(slots)
        self._checker = checker
        self._avoid = avoid_collisions
        self._ik = ik
        self._cubes = dict(cube_bodies)
        self._hand = int(hand_body)
        self._X_HG = X_hand_grasp
        self._timing = timing
        self._params = params
        self._action_port = self.DeclareAbstractInputPort(
            "action", AbstractValue.Make(ActionCommand(0, None))
        )
        self._poses_port = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()])
        )
        initial = Progress(JointTrajectory(np.asarray(q_start, float)))
        self._state_index = self.DeclareAbstractState(AbstractValue.Make(initial))
        self.DeclareVectorOutputPort(
            "reference",
            REFERENCE_SIZE,
            self._calc_reference,
            prerequisites_of_calc={
                self.time_ticket(),
                self.abstract_state_ticket(self._state_index),
            },
        )
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)

    def progress(self, context) -> Progress:
        return context.get_abstract_state(self._state_index).get_value()

    def _world(self, context, held: str | None) -> WorldView:
        poses = self._poses_port.Eval(context)
        cubes = {name: poses[i] for name, i in self._cubes.items()}
        return WorldView(cubes, poses[self._hand] @ self._X_HG, held, self._slots)

    def _update(self, context, state) -> None:
        prog: Progress = context.get_abstract_state(self._state_index).get_value()
        if prog.error is not None:
            return
        t = context.get_time()
        if prog.working >= 0:
            if t >= prog.trajectory.end_time - 1e-9:
                new = replace(prog, working=-1, done=prog.done + 1)
                state.get_mutable_abstract_state(self._state_index).set_value(new)
            return
        cmd: ActionCommand = self._action_port.Eval(context)
        if cmd.action is None or cmd.index != prog.done:
            return
        traj = prog.trajectory.copy()
        if t > traj.end_time:
            traj.hold(t - traj.end_time, "idle", -1)
        held = cmd.action.args[0] if cmd.action.name in PICK_ACTIONS else None
        try:
            motion = solve_action(
                cmd.action,
                cmd.index,
                self._world(context, prog.held),
                self._ik,
                traj,
                self._timing,
                self._params,
                self._checker,
                self._avoid,
            )
            warnings = prog.warnings + tuple(motion.warnings(cmd.index, cmd.action))
            new = replace(prog, trajectory=traj, working=cmd.index, held=held, warnings=warnings)
        except ExecutionError as e:
            new = replace(prog, working=-1, error=str(e))
        state.get_mutable_abstract_state(self._state_index).set_value(new)

    def _calc_reference(self, context, output) -> None:
        prog: Progress = context.get_abstract_state(self._state_index).get_value()
        t = context.get_time()
        q, v, a = prog.trajectory.evaluate(t)
        g, g_rate, phase, action = prog.trajectory.labels(t)
        out = output.get_mutable_value()
        out[0:7], out[7:14], out[14:21] = q, v, a
        out[21:25] = (g, g, g_rate, g_rate)
        out[25:28] = (prog.done, phase, action)
