"""``PolicySource``: a policy in the Diagram, in place of the action source and WaypointIk.

.. pydrake_system::

    name: PolicySource
    input_ports:
    - arm_state
    - hand_state
    - body_poses
    - image_<camera> (one per camera)
    output_ports:
    - desired_state
    - desired_acceleration
    - finger_state
    - actions_done
    - labels

Every ``1 / rate_hz`` simulated seconds its one update builds the observation
(:mod:`cake_drake.policy.observations`) from the measured state and the cameras, asks the
policy for an action (guarded: what the policy raises, returns wrongly or overruns is one
line naming it), turns it into 7 joint targets and a gripper width
(:mod:`cake_drake.policy.spaces`) and holds them until the next update. The outputs are
the same named reference ports ``WaypointIk`` has, so the controller, the plant, the
loggers and the verdict are unchanged. The policy object is Python state outside the
Context: one Diagram, one policy.

The observation is computed once per control period and kept: whoever reads it at the
same simulated time (the policy at the update, a Gym environment between steps) gets the
same object, and each camera renders at most once, on its first read.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem
from pydrake.systems.sensors import ImageRgba8U

from cake_drake.plugins import DURING, PluginError, guarded
from cake_drake.policy import spaces
from cake_drake.policy.observations import Observation, environment_state, goal_table, pose7
from cake_drake.scenario import ACT_BUDGET_S
from cake_drake.systems.waypoint_ik import WorldIndices, declare_reference_ports, hold_target
from cake_drake.world.facts import GoalReading, read_goal


@dataclass
class PolicyTask:
    """What a policy is told at reset: the goal in words and facts, the cubes."""

    instruction: str
    goal: tuple[str, ...]
    cubes: tuple[str, ...]
    problem: object = None  # the symbolic Problem (for a policy that plans)
    scenario: object = None  # the run's Scenario (for a policy that simulates ahead)
    action_space: str = "joint_position"  # what the policy is to answer in
    rate_hz: float = 10.0
    options: dict | None = None
    goal_table: np.ndarray | None = None  # (12, 13): the goal as numbers (observations.py)
    goal_facts: frozenset = frozenset()  # the goal in the world's canonical facts

    def __post_init__(self) -> None:
        if self.problem is not None:
            from cake_drake.symbolic.roles import blocksworld_view

            self.goal_facts = frozenset(blocksworld_view(self.problem).goal)
            if self.goal_table is None:
                self.goal_table = goal_table(self.cubes, self.goal_facts)


def goal_progress(poses, finger: float, goal: frozenset, X_WG=None) -> GoalReading:
    """The goal as the measured world shows it (:func:`cake_drake.world.facts.read_goal`,
    the verdict's own reading)."""
    return read_goal(poses, goal, X_WG, finger)


class PolicySource(LeafSystem):
    """See the module's docstring."""

    def __init__(
        self,
        policy,
        label: str,
        space: str,
        options: dict,
        rate_hz: float,
        max_steps: int,
        world: WorldIndices,
        ik,
        limits: tuple[np.ndarray, np.ndarray],
        q_start: np.ndarray,
        cameras: Sequence[str],
        task: PolicyTask,
        stop_at_goal: bool = True,
        act_budget_s: float | None = ACT_BUDGET_S,
        smooth_s: float = 0.0,
    ) -> None:
        super().__init__()
        #: End the policy's run when the measured world shows the goal (as the Gym env's
        #: episode ends), so a policy that never says done is judged on what it built.
        self.stop_at_goal = stop_at_goal
        self.policy, self.label, self.space, self.options = policy, label, space, dict(options)
        self.max_steps, self.world, self.ik, self.limits = max_steps, world, ik, limits
        self.task = task
        self.counts = spaces.Counts()
        self.done = False
        #: Why the policy stopped acting when it was not its own word (its budget ran out).
        self.ended: str | None = None
        self.period_s = 1.0 / rate_hz
        self.steps = 0
        self.last_action: np.ndarray | None = None
        self._chunk: deque = deque()
        self._observed: tuple | None = None
        #: Wall-clock budget (s) of one call to ``act`` (the scenario's); a policy may carry
        #: its own, None: none (the Gym env's adapter, which only hands over a step).
        self._budget_s = getattr(policy, "act_budget_s", act_budget_s)
        self._box = spaces.bounds(space, self.options, *limits)  # the action's (low, high)
        self._fingers = np.zeros(4)
        self._count, self._labels = np.zeros(1), np.zeros(2)
        self._written: tuple | None = None
        self._q = np.asarray(q_start, float).copy()
        self._width = spaces.GRIPPER_MAX
        self._arm = self.DeclareVectorInputPort("arm_state", 14)
        self._hand = self.DeclareVectorInputPort("hand_state", 4)
        self._poses = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()])
        )
        self._images = {
            name: self.DeclareAbstractInputPort(f"image_{name}", AbstractValue.Make(ImageRgba8U()))
            for name in cameras
        }
        self._settle_s = smooth_s
        self._groups = declare_reference_ports(self, self._q, smooth_s)
        self.DeclarePeriodicUnrestrictedUpdateEvent(1.0 / rate_hz, 0.0, self._update)

    # --- what the policy sees -------------------------------------------------------

    def observe(self, context) -> Observation:
        """The observation now (see :mod:`cake_drake.policy.observations`), computed once
        per simulated time and step; its images render on their first read."""
        key = (context.get_time(), self.steps)
        if self._observed is not None:
            (t, steps), obs = self._observed
            if steps == key[1] and abs(t - key[0]) <= 1e-9:  # the same instant
                return obs
        arm = self._arm.Eval(context)
        hand = self._hand.Eval(context)
        poses = self._poses.Eval(context)
        X_WG = poses[self.world.hand_body].multiply(self.world.X_hand_grasp)
        cubes = self.task.cubes
        X_cubes = {c: poses[self.world.cube_bodies[c]] for c in cubes}
        cube7 = np.array([pose7(X_cubes[c]) for c in cubes], np.float32).reshape(len(cubes), 7)
        goal = self.task.goal_table
        if goal is None:
            goal = np.zeros((12, 13), np.float32)
        values = {
            "observation.state": np.r_[arm[:7], hand[0] + hand[1]].astype(np.float32),
            "observation.velocity": np.asarray(arm[7:], np.float32),
            "observation.ee_pose": pose7(X_WG),
            "observation.cubes": cube7,
            "observation.environment_state": environment_state(cube7, goal),
            "cubes": cubes,
            "task": self.task.instruction,
            "goal": self.task.goal,
            "time": float(context.get_time()),
            "step": self.steps,
        }
        images = {
            f"observation.images.{name}": (
                lambda port=port: np.array(port.Eval(context).data[:, :, :3])
            )
            for name, port in self._images.items()
        }
        obs = Observation(values, images)
        #: The measured poses behind it (cube name -> X_WB, the grasp frame's X_WG) and each
        #: finger's opening (m).
        obs.cube_poses, obs.X_WG, obs.finger = X_cubes, X_WG, float(hand[0])
        self._observed = (key, obs)
        return obs

    def progress(self, obs: Observation) -> GoalReading:
        """How much of the goal the world in ``obs`` shows (read once per observation)."""
        found = getattr(obs, "progress", None)
        if found is None:
            found = goal_progress(obs.cube_poses, obs.finger, self.task.goal_facts, obs.X_WG)
            obs.progress = found
        return found

    # --- one step -----------------------------------------------------------------------

    def _update(self, context, state) -> None:
        if self.done:
            return
        if self.steps >= self.max_steps:
            self.done = True
            self.ended = spaces.budget_text(self.max_steps, 1.0 / self.period_s)
            return
        if not self._chunk:
            obs = self.observe(context)
            if self.stop_at_goal and self.task.goal_facts and self.progress(obs).reached:
                self.done = True  # the goal holds: the run's verdict reads it
                return
            answer = guarded(
                self.label, self.policy.act, obs, exit_code=DURING, budget_s=self._budget_s
            )
            action, said_done = spaces.read_answer(answer, self.label)
            if said_done and action is None:
                self.done = True
                return
            lower, upper = self.limits
            a = spaces.checked(
                action, self.space, self.options, self.label, lower, upper, self.counts, self._box
            )
            self.last_action = a
            if self.space == "joint_chunk":
                self._chunk.extend(a[: spaces.periods(self.space, self.options)])
            elif self.space == "ee_delta":
                q = spaces.ee_target(a[:6], obs.X_WG, self.ik, self._q, self.counts)
                if q is not None:
                    self._q = q
                self._width = float(a[6]) * spaces.GRIPPER_MAX
            else:
                self._q, self._width = a[:7].copy(), float(a[7])
            if said_done:
                self.done = True
        if self._chunk:
            row = self._chunk.popleft()
            self._q, self._width = np.array(row[:7]), float(row[7])
        self.steps += 1
        self.counts.steps = self.steps
        # Only what changed is written (desired_acceleration stays zero).
        held = (self._q.tobytes(), self._width)
        if held != self._written:
            self._written = held
            self._fingers[:2] = self._width / 2
            hold_target(self._groups, context, state, self._q, self._settle_s)
            state.get_mutable_discrete_state(self._groups["finger_state"]).set_value(self._fingers)
        self._count[0] = self.steps
        self._labels[1] = self.steps - 1
        state.get_mutable_discrete_state(self._groups["actions_done"]).set_value(self._count)
        state.get_mutable_discrete_state(self._groups["labels"]).set_value(self._labels)

    def finished(self) -> bool:
        return self.done


def make_policy(spec: str, options: dict):
    """The policy ``spec`` (``module:attribute``) names, built with ``options`` (less the
    action space's own); checked for the protocol (``reset``, ``act``)."""
    from cake_drake.plugins import require, resolve

    factory = resolve(spec, {}, "policy")
    policy = factory(**{k: v for k, v in options.items() if k not in ("horizon", "execute")})
    require(policy, spec, "policy", ("reset", "act"))
    return policy


def policy_of(ref) -> tuple[str, dict]:
    """The factory and keyword arguments a ``!Policy`` reference names: its ``factory``
    and ``options``, or, for a ``checkpoint``, the learned layer's adapter (through the
    plug-in door) with the folder and device."""
    if ref.checkpoint:
        from cake_drake.paths import resolve_path
        from cake_drake.scenario import CHECKPOINT_POLICY

        return CHECKPOINT_POLICY, {"path": str(resolve_path(ref.checkpoint)), "device": ref.device}
    return ref.factory, dict(ref.options)


__all__ = ["PolicySource", "PolicyTask", "make_policy", "PluginError"]
