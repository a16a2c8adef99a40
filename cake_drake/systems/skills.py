"""``LearnedSkills``: the geometric layer learned, one ground action at a time.

.. pydrake_system::

    name: LearnedSkills
    input_ports:
    - action
    - body_poses
    - arm_state
    - hand_state
    output_ports:
    - desired_state
    - desired_acceleration
    - finger_state
    - actions_done
    - labels
    - infeasible

The same ports as :class:`~cake_drake.systems.waypoint_ik.WaypointIk`: the action source
(the planner's plan, the execution monitor) gives a ground action; where ``WaypointIk``
would compute waypoints and IK, a learned skill is asked every ``1 / rate_hz`` simulated
seconds for its action. Each control period reads as measure → observe → the shield's
observation steps → the skill → its action steps → IK → write; the steps are
:mod:`cake_drake.policy.shield`'s, those ``motion.skill_rules`` names (``[]``: the network
alone), and how often each changed the network's answer goes in the run's summary.

The skill is any object with ``reset()`` (a new action: no history) and
``act(observation)``; a checkpoint's adapter is made through the plug-in door, so nothing
here imports the learning code. It reads the joints and the action's own numbers
(``observation.skill``, fixed when the action starts as the classical layer fixes its
waypoints) or, never seeing the arm, those numbers from the hand and the gripper's width
(``observation.relative``). Its ``action_space`` (default ``joint_position``) says what it
answers (:mod:`cake_drake.policy.spaces`): ``joint_position``, the seven joint targets
and the gripper's width; ``ee_delta``, a move of the grasp frame (dx dy dz droll dpitch
dyaw, world axes; the hand kept pointing down, turned by dyaw) and the gripper (0 closed,
1 open), turned into joints by damped least squares
(:class:`cake_drake.geometric.ik.DlsIk`, seeded at the last target; a move it cannot reach
keeps the last target). With ``smooth_s`` > 0 the joint targets reach the controller
through a critically damped filter that settles in about ``smooth_s``.

An action ends when its effects hold in the measured world (:func:`effects_hold`), when
it runs out of its ``budget`` of control periods, or when an ``end`` step ends its try:
``actions_done`` counts it and the action source judges the world. The same ground
action failing :data:`MAX_TRIES` times in a row stops the run, named; so does a skill
that answers NaN (exit 3, naming the skill and the action).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem

from cake_drake.errors import ExecutionError
from cake_drake.geometric.waypoints import WaypointParams
from cake_drake.plugins import DURING, guarded
from cake_drake.policy import shield, spaces
from cake_drake.policy.observations import (
    SkillContext,
    relative_vector,
    skill_context,
    skill_vector,
)
from cake_drake.policy.shield import GRIPPER_MAX, STILL_END_S, STOPPED_M, Answer, Period
from cake_drake.scenario import ACT_BUDGET_S
from cake_drake.symbolic import GroundAction
from cake_drake.systems.plan_source import MAX_TRIES, ActionCommand, Refusal
from cake_drake.systems.waypoint_ik import (
    WorldIndices,
    declare_reference_ports,
    hold_target,
    reference_target,
)
from cake_drake.world.facts import read_facts
from cake_drake.world.scene import CUBE_SIZE

#: m below the transit height the grasp frame may be when a pick or a place counts as done.
LIFT_TOL = 0.02
#: Control periods an action may take (15 s at 10 Hz) unless the scenario says.
DEFAULT_BUDGET = 150
#: The action spaces a skill may answer in, and how many numbers each answer has.
SKILL_SPACES = {"joint_position": 8, "ee_delta": 7}


def effects_hold(
    context: SkillContext, cubes, X_WG: RigidTransform, finger: float, clearance: float = 0.05
) -> bool:
    """Whether the action of ``context`` is done in the measured world, ending where the
    classical layer's would (so the next action starts from where its demonstrations
    did): picked (the cube held, the hand up at the transit height) or placed (resting on
    its support or the table, the hand open and back up at the transit height, which now
    clears the cube just placed by ``clearance``)."""
    facts = read_facts(cubes, X_WG=X_WG, finger_opening=finger).facts
    z = X_WG.translation()[2]
    if context.target is None:  # pick-up, unstack
        return ("holding", context.cube) in facts and z >= context.z_transit - LIFT_TOL
    rests = ("on", context.cube, context.other) if context.other else ("on-table", context.cube)
    above = cubes[context.cube].translation()[2] + CUBE_SIZE + clearance
    up = z >= max(context.z_transit, above) - LIFT_TOL
    return rests in facts and ("arm-empty",) in facts and up


@dataclass(frozen=True)
class SkillProgress:
    """Immutable: Drake's state copies share it. Read as ``WaypointIk``'s ``Progress``."""

    working: int = -1  # index of the action under way, -1 when idle
    action: GroundAction | None = None  # the action under way, in the domain's names
    context: SkillContext | None = None
    steps: int = 0  # control periods of the action under way
    tries: int = 0  # ends without effects of the same action, in a row
    last_failed: GroundAction | None = None
    error: str | None = None
    warnings: tuple[str, ...] = ()
    #: Totals for the run's summary: actions ended by their effects, by their budget, by
    #: an ``end`` step of the shield (the hand stood still), and the skill's periods.
    succeeded: int = 0
    ran_out: int = 0
    stalled: int = 0
    total_steps: int = 0
    #: rad: the yaw the hand keeps to through the action (the ``keep_wrist_mid_range`` step).
    wrist: float | None = None
    #: m: where the hand was measured at the last period (x y z).
    hand: tuple[float, float, float] | None = None
    #: Control periods in a row the hand has stood still (moved less than ``STOPPED_M``).
    still: int = 0

    @property
    def done(self) -> int:
        """Actions ended, however they ended."""
        return self.succeeded + self.ran_out + self.stalled

    def __deepcopy__(self, memo):
        return self


class LearnedSkills(LeafSystem):
    """See the module's docstring. ``meaning`` maps the domain's ground action to the
    exercise's names (as ``WaypointIk``'s); ``label`` names the skill in messages;
    ``rules`` names the shield's steps (:data:`cake_drake.policy.shield.DEFAULT`)."""

    def __init__(
        self,
        skill,
        label: str,
        world: WorldIndices,
        q_start: np.ndarray,
        rate_hz: float,
        budget: int,
        meaning: Callable[[GroundAction], GroundAction],
        waypoints=None,
        ik=None,
        smooth_s: float = 0.0,
        rules=shield.DEFAULT,
    ) -> None:
        super().__init__()
        self.skill, self.label, self.world = skill, label, world
        self.space = getattr(skill, "action_space", "joint_position")
        if self.space not in SKILL_SPACES:
            raise ExecutionError(
                f"skill {label!r}: action_space {self.space!r}; a skill answers in "
                f"{' or '.join(SKILL_SPACES)}"
            )
        if self.space == "ee_delta" and ik is None:
            raise ValueError("an ee_delta skill needs an ik (DlsIk) to turn moves into joints")
        self.ik, self.counts = ik, spaces.Counts()
        #: The ee_delta space's bounds (low, high), which every answer is clipped to.
        self._box = spaces.bounds("ee_delta", {}, None, None)
        #: The skill reads every yaw modulo a quarter turn (a cube's faces are alike), so
        #: the hand may take whichever quarter turn of its answer keeps the wrist mid-range.
        self._free_turns = bool(getattr(skill, "free_quarter_turns", False))
        #: The shield's steps that run for this skill's action space, by phase, in order.
        ran = [shield.STEPS[n] for n in shield.check_names(rules)]
        self.steps = tuple(s for s in ran if self.space in s.spaces)
        self._phase = {
            ph: tuple(s for s in self.steps if s.phase == ph)
            for ph in ("end", "observation", "action")
        }
        #: How often each step changed the network's answer, by the action's schema.
        self.changed: dict[str, Counter] = {s.name: Counter() for s in self.steps}
        self.budget, self.meaning = budget, meaning
        self._params = waypoints or WaypointParams()
        #: Wall-clock budget (s) of one answer (a skill may carry its own, as a policy does).
        self._budget_s = getattr(skill, "act_budget_s", ACT_BUDGET_S)
        self.period_s = 1.0 / rate_hz
        self.smooth_s = smooth_s
        self._action = self.DeclareAbstractInputPort(
            "action", AbstractValue.Make(ActionCommand(0, None))
        )
        self._poses = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()])
        )
        self._arm = self.DeclareVectorInputPort("arm_state", 14)
        self._hand = self.DeclareVectorInputPort("hand_state", 4)
        self._state = self.DeclareAbstractState(AbstractValue.Make(SkillProgress()))
        self._groups = declare_reference_ports(self, q_start, self.smooth_s)
        self.DeclareAbstractOutputPort(
            "infeasible",
            lambda: AbstractValue.Make(Refusal()),
            lambda context, out: out.set_value(Refusal()),  # a skill refuses nothing ahead
        )
        self.DeclarePeriodicUnrestrictedUpdateEvent(self.period_s, 0.0, self._update)

    # --- what the rest of the run reads (as WaypointIk's) ---------------------------------

    checker = None  # no planned moves to check
    planning = None

    def progress(self, context) -> SkillProgress:
        return context.get_abstract_state(self._state).get_value()

    def shield_summary(self) -> dict:
        """Each step that ran, and how often it changed the network's answer: in all and
        by the action's schema."""
        return {
            name: {"changed": sum(c.values()), "by_action": dict(sorted(c.items()))}
            for name, c in self.changed.items()
        }

    # --- one control period ---------------------------------------------------------------

    def _measure(self, context):
        poses = self._poses.Eval(context)
        w = self.world
        cubes = {name: poses[i] for name, i in w.cube_bodies.items()}
        X_WG = poses[w.hand_body] @ w.X_hand_grasp
        return cubes, X_WG, float(self._hand.Eval(context)[0])

    def _update(self, context, state) -> None:
        prog = self.progress(context)
        if prog.error is not None:
            return
        cubes, X_WG, finger = self._measure(context)
        if prog.working < 0:
            prog = self._start(context, prog, cubes)
            if prog.working < 0 or prog.error is not None:
                self._set(state, prog)
                return
        if effects_hold(prog.context, cubes, X_WG, finger, self._params.transit_clearance):
            self._set(state, self._end(prog, True))
            return
        if prog.steps >= self.budget:
            self._set(state, self._end(prog, False))
            return
        if self.space == "ee_delta" and prog.hand is not None:
            moved = np.linalg.norm(X_WG.translation() - prog.hand) >= STOPPED_M
            prog = replace(prog, still=0 if moved else prog.still + 1)
        period = self._period(context, prog, cubes, X_WG)
        for step in self._phase["end"]:
            if step.run(period):
                self.changed[step.name][prog.context.schema] += 1
                self._set(state, self._end(replace(prog, stalled=prog.stalled + 1), False))
                return
        observation = self._observe(context, period, count=True)
        answer = self._ask(observation, prog)
        if self.space == "ee_delta":
            move = np.clip(answer, *self._box)
            self.counts.clipped += int(not np.array_equal(move, answer))
            shaped = self._shape(
                period, Answer(move[:6], float(move[6]) * GRIPPER_MAX, X_WG, prog.wrist)
            )
            last = reference_target(self._groups, context)
            q = spaces.ee_target(shaped.move, shaped.base, self.ik, last, self.counts, down=True)
            prog = replace(prog, hand=tuple(X_WG.translation()), wrist=shaped.wrist)
            target = last if q is None else q
        else:
            width = float(np.clip(answer[7], 0.0, GRIPPER_MAX))
            shaped = self._shape(period, Answer(np.zeros(6), width, X_WG))
            target = answer[:7]
        hold_target(self._groups, context, state, target, self.smooth_s)
        half = shaped.width / 2
        fingers = np.array([half, half, 0.0, 0.0])
        state.get_mutable_discrete_state(self._groups["finger_state"]).set_value(fingers)
        self._set(state, replace(prog, steps=prog.steps + 1, total_steps=prog.total_steps + 1))

    def _period(self, context, prog: SkillProgress, cubes, X_WG) -> Period:
        """What the shield's steps read this period."""
        hand = self._hand.Eval(context)
        sent = None
        if self.space == "ee_delta":  # where the hand was last sent
            sent = self.ik.kin.pose(reference_target(self._groups, context)).translation()
        fingers = 2.0 * context.get_discrete_state(self._groups["finger_state"]).get_value()[0]
        return Period(
            prog.context, cubes, X_WG, float(hand[0] + hand[1]), self._params, self.period_s,
            fingers=fingers, sent=sent, still_s=prog.still * self.period_s,
            max_turn=float(self._box[1][5]), free_turns=self._free_turns,
        )  # fmt: skip

    def _ask(self, observation: dict, prog: SkillProgress) -> np.ndarray:
        """The skill's answer, guarded as every plug-in's (what it raises, or an answer
        slower than its budget, stops the run in one line naming the skill), and checked:
        the space's count of finite numbers."""
        raw = guarded(f"skill {self.label!r}", self.skill.act, observation, exit_code=DURING,
                      budget_s=self._budget_s)  # fmt: skip
        size = SKILL_SPACES[self.space]
        try:
            answer = np.asarray(raw, float).reshape(-1)
        except (TypeError, ValueError):  # not numbers at all
            answer = None
        if answer is None or answer.shape != (size,) or not np.all(np.isfinite(answer)):
            shown = repr(raw) if answer is None else np.array2string(answer, precision=3)
            what = (
                "7 joint targets, the gripper's width"
                if size == 8
                else "a move of the hand, dx dy dz droll dpitch dyaw, and the gripper"
            )
            raise ExecutionError(
                f"skill {self.label!r} answered {shown[:60]} "
                f"for {prog.action} (action {prog.working + 1}); a {self.space} skill "
                f"answers {size} finite numbers ({what})"
            )
        return answer

    def _shape(self, period: Period, answer: Answer) -> Answer:
        """The shield's action steps over the network's answer, each change counted."""
        for step in self._phase["action"]:
            shaped = step.run(period, answer)
            if not shaped.same_as(answer):
                self.changed[step.name][period.action.schema] += 1
            answer = shaped
        return answer

    def _observe(self, context, period: Period, count: bool = False) -> dict:
        arm = self._arm.Eval(context)
        skill = skill_vector(period.action, period.cubes, period.X_WG)
        relative = skill
        for step in self._phase["observation"]:
            shaped = step.run(period, relative)
            if count and not np.array_equal(shaped, relative):
                self.changed[step.name][period.action.schema] += 1
            relative = shaped
        return {
            "observation.state": np.r_[arm[:7], period.width].astype(np.float32),
            "observation.skill": skill,
            # What a skill that never sees the arm reads: no joint, no absolute height.
            "observation.relative": relative_vector(relative, period.width),
        }

    def observe(self, context) -> dict | None:
        """What the skill reads now about the action under way (None when idle): the
        skill environment's observation between two of this system's updates."""
        prog = self.progress(context)
        if prog.context is None:
            return None
        cubes, X_WG, _ = self._measure(context)
        width = float(sum(self._hand.Eval(context)[:2]))
        return self._observe(context, Period(prog.context, cubes, X_WG, width, self._params))

    def _start(self, context, prog: SkillProgress, cubes) -> SkillProgress:
        cmd = self._action.Eval(context)
        if not (isinstance(cmd, ActionCommand) and isinstance(cmd.index, int)):
            return replace(prog, error=f"the action source gave {cmd!r:.80}; it gives an "
                           "ActionCommand(index: int, action: GroundAction or None)")  # fmt: skip
        if cmd.action is None or cmd.index != prog.done:
            return prog
        try:
            meaning = self.meaning(cmd.action)
            ctx = skill_context(meaning, cubes, self.world.slots, self._params)
        except Exception as e:  # noqa: BLE001 - an action the skill cannot take, named
            return replace(prog, error=f"action {cmd.index + 1} {cmd.action}: {e}")
        guarded(f"skill {self.label!r}", self.skill.reset, exit_code=DURING,
                budget_s=self._budget_s)  # fmt: skip
        return replace(
            prog,
            working=cmd.index,
            action=cmd.action,
            context=ctx,
            steps=0,
            wrist=None,
            hand=None,
            still=0,
        )

    def _end(self, prog: SkillProgress, held: bool) -> SkillProgress:
        """The action is over: counted done for the action source to judge (``stalled``
        already counted when an ``end`` step ended it)."""
        tries = 0 if held else (prog.tries + 1 if prog.last_failed == prog.action else 1)
        stood = "end_try_when_still" in self.changed and prog.still * self.period_s >= STILL_END_S
        error = None
        if tries >= MAX_TRIES:
            error = (
                f"skill {self.label!r} did not do {prog.action} in {MAX_TRIES} tries of "
                f"{self.budget} steps each"
            )
            if stood:
                error += f"; the last ended with the hand still for {STILL_END_S:g} s"
        return replace(
            prog,
            working=-1,
            context=None,
            steps=0,
            tries=tries,
            last_failed=None if held else prog.action,
            error=error,
            succeeded=prog.succeeded + held,
            ran_out=prog.ran_out + (not held and not stood),
        )

    def _set(self, state, prog: SkillProgress) -> None:
        state.get_mutable_abstract_state(self._state).set_value(prog)
        count = np.array([float(prog.done)])
        state.get_mutable_discrete_state(self._groups["actions_done"]).set_value(count)
        # The phase a plot shades (cake_drake.formats.PHASE_NAMES): a skill has no phases
        # of its own, so a pick is shaded as the classical pick's first (pre-grasp) and a
        # place as the classical place's first (transport); idle between actions.
        if prog.context is None:
            phase = 0.0
        else:
            phase = 1.0 if prog.context.target is None else 4.0
        labels = np.array([phase, float(prog.working)])
        state.get_mutable_discrete_state(self._groups["labels"]).set_value(labels)
