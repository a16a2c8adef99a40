"""``WaypointIk``: the geometric layer inside the Diagram."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from itertools import accumulate

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem

from cake_drake.dynamic.reference import REFERENCE_PORTS
from cake_drake.errors import CakeDrakeError, ExecutionError, IkError
from cake_drake.geometric.collisions import CollisionChecker
from cake_drake.geometric.ik import IkSolver
from cake_drake.geometric.solve import Planning, refine_action, release_action, solve_action
from cake_drake.geometric.trajectory import JointLimits, JointTrajectory, Timing
from cake_drake.geometric.waypoints import PICK_ACTIONS, WaypointParams, WorldView
from cake_drake.symbolic import GroundAction
from cake_drake.systems.plan_source import ActionCommand, Refusal

#: A critically damped filter of rate w is within 2 % of a step from rest after
#: SETTLE_RATE / w seconds: (1 + x) exp(-x) = 0.02.
SETTLE_RATE = 5.84


def declare_reference_ports(
    system: LeafSystem, q_start: np.ndarray, smooth_s: float = 0.0
) -> dict[str, int]:
    """Declare :data:`REFERENCE_PORTS` on ``system``, held at the start (``q_start`` at
    rest, fingers open, no action); the discrete state groups' indices by port name. For
    a system that writes the reference at its own rate (a policy, a learned skill) rather
    than ``WaypointIk``'s tape: it sets each new joint target with :func:`hold_target`.

    ``smooth_s`` 0: each target is held as a step (``desired_state`` a state output, zero
    velocity): the controller is kicked at every step. ``smooth_s`` > 0: the reference
    follows the targets through a critically damped second-order filter that settles on
    a new target in ``smooth_s`` (from rest, within 2 % of the move: its rate
    :data:`SETTLE_RATE` / ``smooth_s``): position and velocity
    continuous, so computed torque follows a motion instead of a staircase. Between
    targets the filter is solved exactly; ``desired_state`` is computed from the group
    ``smooth`` (the target, the position and velocity when it was set, and that time)
    and the context's time; ``desired_acceleration`` stays zero (the feedback's, not a
    feedforward that would jump with every target)."""
    initial = {
        "desired_state": np.r_[np.asarray(q_start, float), np.zeros(7)],
        "desired_acceleration": np.zeros(7),
        "finger_state": np.array([0.04, 0.04, 0.0, 0.0]),
        "actions_done": np.zeros(1),
        "labels": np.array([0.0, -1.0]),
    }
    groups = {}
    for name, size in REFERENCE_PORTS.items():
        assert initial[name].shape == (size,)
        if smooth_s > 0 and name == "desired_state":
            continue
        groups[name] = system.DeclareDiscreteState(initial[name])
        system.DeclareStateOutputPort(name, groups[name])
    if smooth_s > 0:
        smooth = groups["smooth"] = system.DeclareDiscreteState(
            np.r_[q_start, q_start, np.zeros(7), 0.0]
        )
        needs = {system.time_ticket(), system.discrete_state_ticket(smooth)}

        def desired_state(context, out) -> None:
            q, v = _smooth_at(context, smooth, smooth_s)
            out.SetFromVector(np.r_[q, v])

        system.DeclareVectorOutputPort("desired_state", 14, desired_state, needs)
    return groups


def _smooth_at(context, group: int, smooth_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The filtered reference's position and velocity at the context's time: with the
    error e = q - target, e(t) = (e0 + (v0 + w e0) t) exp(-w t)."""
    r = context.get_discrete_state(group).value()
    target, q0, v0 = r[:7], r[7:14], r[14:21]
    w, t = SETTLE_RATE / smooth_s, max(context.get_time() - r[21], 0.0)
    e0 = q0 - target
    b = v0 + w * e0
    decay = np.exp(-w * t)
    return target + (e0 + b * t) * decay, (v0 - w * b * t) * decay


def hold_target(groups: dict[str, int], context, state, q: np.ndarray, smooth_s: float = 0.0):
    """Make ``q`` (7 joint targets) the reference from now on: held at once (``smooth_s``
    0) or approached smoothly from where the reference is now (see
    :func:`declare_reference_ports`)."""
    if "smooth" in groups:
        here, velocity = _smooth_at(context, groups["smooth"], smooth_s)
        row = np.r_[q, here, velocity, context.get_time()]
        state.get_mutable_discrete_state(groups["smooth"]).set_value(row)
    else:
        state.get_mutable_discrete_state(groups["desired_state"]).set_value(np.r_[q, np.zeros(7)])


def reference_target(groups: dict[str, int], context) -> np.ndarray:
    """The last joint target set (a seed for the next one's IK)."""
    group = groups.get("smooth", groups.get("desired_state"))
    return context.get_discrete_state(group).value()[:7].copy()


@dataclass(frozen=True)
class WorldIndices:
    """Where ``WaypointIk`` finds things in the plant's ``body_poses`` output."""

    cube_bodies: Mapping[str, int]  # block name -> body index
    hand_body: int
    X_hand_grasp: RigidTransform  # grasp frame in the hand body's frame
    slots: tuple[tuple[float, float], ...]  # table slots (x, y) for put-down


def _as_is(action: GroundAction) -> GroundAction:
    return action


@dataclass(frozen=True)
class MotionSettings:
    """How ``WaypointIk`` turns actions into moves (the scenario's ``motion`` section).

    ``meaning`` maps the domain's ground action to the exercise's names (``pick-up``,
    ``unstack``, ``put-down``, ``stack``): what the action *does*, read from the domain's
    schemas (:meth:`cake_drake.symbolic.roles.GroundRole.canonical`), so that any
    Blocksworld naming runs.
    """

    timing: Timing
    waypoints: WaypointParams
    checker: CollisionChecker | None = None  # report moves that sweep through cubes
    avoid_collisions: bool = False
    meaning: Callable[[GroundAction], GroundAction] = _as_is
    #: Motions chosen free and blocked moves planned (a planner other than ``straight``).
    planning: Planning | None = None
    #: The action source listens on ``infeasible``: an action that cannot be done is
    #: refused (:class:`Refusal`) instead of stopping the run.
    feedback: bool = False


def _slices(sizes: dict[str, int]) -> dict[str, slice]:
    ends = accumulate(sizes.values())
    return {name: slice(end - sizes[name], end) for name, end in zip(sizes, ends, strict=True)}


#: Where each reference port's value sits in a row of :class:`Tape`.
_SLICES = _slices(REFERENCE_PORTS)


@dataclass(frozen=True)
class Tape:
    """The reference at every step from the last decision until the trajectory ends, one
    row per step (the ports' values side by side, see :data:`REFERENCE_PORTS`), computed
    at once when the trajectory changes: between decisions a step only reads its row.
    Past the last row the reference holds still (the trajectory has ended)."""

    period: float
    k0: int  # step index of the first row (its time is k0 * period)
    times: np.ndarray
    rows: np.ndarray

    def row(self, t: float) -> np.ndarray | None:
        """The row for time ``t``, or None when ``t`` is not one of the tape's steps."""
        n = len(self.times)
        if n and t > self.times[-1]:
            return self.rows[-1]
        i = round(t / self.period) - self.k0
        return self.rows[i] if 0 <= i < n and self.times[i] == t else None

    def __deepcopy__(self, memo):
        return self


@dataclass(frozen=True)
class Progress:
    """Immutable snapshot of execution: Drake's state copies share it instead of copying."""

    trajectory: JointTrajectory
    working: int = -1  # index of the action being executed, -1 when idle
    done: int = 0  # actions finished
    held: str | None = None  # cube in the hand, by the plan
    #: A place whose last moves are still to be planned from the world as measured when
    #: the arm gets there: (the action as the geometric layer reads it, the domain's own
    #: name of it, the waypoint parameters it was planned with, the pose commanded at
    #: the place when the arm is on its way down to it, else None).
    pending: tuple[GroundAction, str, WaypointParams, RigidTransform | None] | None = None
    error: str | None = None
    warnings: tuple[str, ...] = ()  # collisions found along the planned moves
    refused: Refusal = Refusal()  # the last action found infeasible before it started
    tape: Tape | None = None  # the reference from the last change on (None: not yet made)

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
        - desired_state
        - desired_acceleration
        - finger_state
        - actions_done
        - labels
        - infeasible

    When ``action`` names an action it has not started, it reads the cube and gripper
    poses from ``body_poses`` (the plant's), computes the waypoints, solves IK and
    appends the moves (:func:`cake_drake.geometric.solve.solve_action`). The outputs
    are the arm's desired state [q_d, v_d] and acceleration a_d, the fingers' desired
    state [q1, q2, v1, v2], the number of actions done, and [phase index, action index]
    (see :data:`REFERENCE_PORTS`); an action counts as done once its last move may be
    blended into by the next action's first. The outputs are state, written by the one
    update every ``period``: the reference at the time of that update, as a discrete
    plant stepping at the same period reads it. An IK failure stops execution and is
    kept in the state (``Progress.error``); collisions found along the planned moves
    (with a ``checker``) are kept as warnings.
    """

    def __init__(
        self,
        ik: IkSolver,
        world: WorldIndices,
        q_start: np.ndarray,
        limits: JointLimits,
        period: float,
        motion: MotionSettings,
    ) -> None:
        super().__init__()
        self._ik = ik
        self._indices = world
        self._motion = motion
        self._period = period
        self._action_port = self.DeclareAbstractInputPort(
            "action", AbstractValue.Make(ActionCommand(0, None))
        )
        self._poses_port = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()])
        )
        initial = Progress(JointTrajectory(np.asarray(q_start, float), limits))
        self._state_index = self.DeclareAbstractState(AbstractValue.Make(initial))
        # The reference at the time of the last update, one discrete state group per
        # port: the ports are the state itself, read without calling back into Python,
        # and one update a step evaluates the trajectory for all of them.
        self._groups = {}
        for name, value in self._reference(initial, 0.0).items():
            self._groups[name] = self.DeclareDiscreteState(value)
            self.DeclareStateOutputPort(name, self._groups[name])
        self.DeclareAbstractOutputPort(
            "infeasible",
            lambda: AbstractValue.Make(Refusal()),
            lambda context, out: out.set_value(self.progress(context).refused),
            prerequisites_of_calc={self.abstract_state_ticket(self._state_index)},
        )
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)

    @staticmethod
    def _reference(prog: Progress, t: float) -> dict[str, np.ndarray]:
        """Every port's value at time ``t`` (see :data:`REFERENCE_PORTS`)."""
        q, v, a, g, rate, phase, action = prog.trajectory.at(t)
        return {
            "desired_state": np.concatenate([q, v]),
            "desired_acceleration": a,
            "finger_state": np.array([g, g, rate, rate]),
            "actions_done": np.array([float(prog.done)]),
            "labels": np.array([float(phase), float(action)]),
        }

    def _tape(self, prog: Progress, t: float) -> Tape:
        """The reference at each step from ``t`` until the trajectory ends (one step past
        it), every row equal to :meth:`_reference`'s at that step's time."""
        h = self._period
        k0 = round(t / h)
        k1 = max(k0, int(prog.trajectory.end_time / h) + 1)
        while k1 * h <= prog.trajectory.end_time:
            k1 += 1
        times = np.arange(k0, k1 + 1) * h
        q, v, a, g, rate, phase, action = prog.trajectory.at_many(times)
        done = np.full(len(times), float(prog.done))
        rows = np.column_stack([q, v, a, g, g, rate, rate, done, phase, action]).astype(float)
        return Tape(h, k0, times, rows)

    @property
    def checker(self) -> CollisionChecker | None:
        """What the planned moves are checked with, if anything."""
        return self._motion.checker

    @property
    def planning(self) -> Planning | None:
        """The motion planner's settings and record of queries, if one plans."""
        return self._motion.planning

    def progress(self, context) -> Progress:
        return context.get_abstract_state(self._state_index).get_value()

    def _world(self, context, held: str | None) -> WorldView:
        poses = self._poses_port.Eval(context)
        w = self._indices
        cubes = {name: poses[i] for name, i in w.cube_bodies.items()}
        return WorldView(cubes, poses[w.hand_body] @ w.X_hand_grasp, held, w.slots)

    def _update(self, context, state) -> None:
        t = context.get_time()
        prog: Progress = context.get_abstract_state(self._state_index).get_value()
        new = self._step(context, prog, t)
        if new is not prog or new.tape is None:
            new = replace(new, tape=self._tape(new, t))
            state.get_mutable_abstract_state(self._state_index).set_value(new)
        row = new.tape.row(t)
        if row is None:  # stepped off the tape's grid (a caller's own step): compute it
            values = self._reference(new, t)
            row = np.concatenate([values[name] for name in REFERENCE_PORTS])
        for name, group in self._groups.items():
            state.get_mutable_discrete_state(group).SetFromVector(row[_SLICES[name]])

    def _step(self, context, prog: Progress, t: float) -> Progress:
        """The progress after this step's decisions (``prog`` itself when unchanged)."""
        if prog.error is not None:
            return prog
        if prog.working >= 0:
            # Done (or ready for the next step) once the last move may be blended into.
            if t >= prog.trajectory.ready_time(self._motion.timing.blend) - 1e-9:
                if prog.pending is not None:
                    return self._refine(context, prog, t)
                return replace(prog, working=-1, done=prog.done + 1)
            return prog
        cmd: ActionCommand = self._action_port.Eval(context)
        if not (
            isinstance(cmd, ActionCommand)
            and isinstance(cmd.index, int)
            and (cmd.action is None or isinstance(cmd.action, GroundAction))
        ):
            return replace(
                prog,
                error=f"the action source gave {cmd!r:.80}; it gives an ActionCommand(index: "
                "int, action: GroundAction or None)",
            )
        if cmd.action is None or cmd.index != prog.done:
            return prog
        if prog.refused.index == cmd.index and prog.refused.action == cmd.action:
            return prog  # refused: the source decides what comes instead
        traj = prog.trajectory.copy()
        traj.resume_at(t, "idle", -1)
        m = self._motion
        try:
            action = m.meaning(cmd.action)
        except CakeDrakeError as e:
            return replace(prog, error=f"action {cmd.index + 1} {cmd.action}: {e}")
        held = action.args[0] if action.name in PICK_ACTIONS else None

        def named(text: str) -> str:  # messages name the domain's own action
            return text.replace(str(action), str(cmd.action))

        try:
            motion = solve_action(
                action,
                cmd.index,
                self._world(context, prog.held),
                self._ik,
                traj,
                m.timing,
                m.waypoints,
                m.checker,
                m.avoid_collisions,
                refine=True,
                planning=m.planning,
            )
            found = tuple(named(w) for w in motion.warnings(cmd.index, action))
            pending = (
                (action, str(cmd.action), motion.params, None) if motion.pending_after else None
            )
            return replace(
                prog,
                trajectory=traj,
                working=cmd.index,
                held=held,
                pending=pending,
                warnings=prog.warnings + found,
                refused=Refusal(),
            )
        except IkError as e:  # before the arm moved: the symbolic layer may choose again
            if m.feedback:
                return replace(prog, refused=Refusal(cmd.index, cmd.action, named(str(e))))
            return replace(prog, working=-1, error=named(str(e)))
        except ExecutionError as e:
            return replace(prog, working=-1, error=named(str(e)))

    def _refine(self, context, prog: Progress, t: float) -> Progress:
        """Above the target: plan the move down to the place pose from the cube's pose in
        the hand and the support's pose as measured now. At the place pose: open the
        fingers where the cube belongs, then retract
        (:func:`cake_drake.geometric.solve.release_action`)."""
        action, own_name, params, X_place = prog.pending
        traj = prog.trajectory.copy()
        traj.resume_at(t, "transport" if X_place is None else "place", prog.working)
        world = self._world(context, prog.held)
        m = self._motion
        try:
            if X_place is None:
                motion = refine_action(
                    action, prog.working, world, self._ik, traj, m.timing, params
                )
                pending = (action, own_name, params, motion.waypoints[0].X_WG)
            else:
                release_action(
                    action, prog.working, world, self._ik, traj, m.timing, params, X_place
                )
                pending = None
        except ExecutionError as e:
            error = str(e).replace(str(action), own_name)
            return replace(prog, working=-1, pending=None, error=error)
        return replace(prog, trajectory=traj, pending=pending)
