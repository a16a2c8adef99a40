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
seconds for its action, from the joints and the action's own numbers (``observation.skill``:
:func:`cake_drake.policy.observations.skill_vector`, its targets fixed when the action
starts as the classical layer fixes its waypoints), or, for a skill that never sees the
arm, from those numbers and the gripper's width alone
(``observation.relative``: :func:`cake_drake.policy.observations.relative_vector`), a
destination further across than ``AROUND`` read on the way around the arm's base, as the
classical layer's transit swings about the first joint (:meth:`LearnedSkills._around`).
The skill is any object with ``reset()`` (a new action: no history) and
``act(observation)``; a checkpoint's adapter is made through the plug-in door, so
nothing here imports the learning code. Its ``action_space`` (an attribute, default
``joint_position``) says what it answers (:mod:`cake_drake.policy.spaces`):

- ``joint_position``: 8 numbers, the arm's seven joint targets and the gripper's width;
- ``ee_delta``: 7 numbers, a move of the grasp frame from where it is measured (dx dy dz
  in m, droll dpitch dyaw in rad, world axes) and the gripper (0 closed, 1 open): the
  hand's frame, as the VLAs answer. Every grasp and place of these tasks is top-down, so
  the hand is kept pointing down, turned by dyaw (droll and dpitch are not used: learned
  tilts add up step after step, and nothing the skill reads measures them). The joints
  come from damped least squares (:class:`cake_drake.geometric.ik.DlsIk`, seeded at the
  last target), as under the demonstrator that recorded such a skill; a move it cannot
  reach keeps the last target. A hand stopped short of where it was last sent takes its
  move from there, at most ``LEAD`` on (:meth:`LearnedSkills._short`); a hand goes down
  only once over where it goes down to, as the classical layer's does from its pre-grasp
  pose, keeps above the cubes beside its way while crossing, and keeps to the transit
  height while further than ``AROUND`` across (:meth:`LearnedSkills._over`); the
  fingers close only around the cube a pick takes and open only where a place's cube
  rests, are open while a pick's cube is out of them and stay open once a place's is,
  and let go where a place's hand has stopped with its cube resting
  (:meth:`LearnedSkills._gripper`).

With ``smooth_s`` > 0, the joint targets reach the controller through a critically
damped filter that settles on each in about ``smooth_s``
(:func:`cake_drake.systems.waypoint_ik.declare_reference_ports`): the controller follows
a motion, continuous in position and velocity, rather than a 10 Hz staircase.

An action ends when its effects hold in the measured world (:func:`effects_hold`): a
picked cube in the closed hand at the transit height, or a placed cube resting where
the action puts it with the hand open and back up at the transit height. It also ends
when it runs out of its ``budget`` of control periods, or, for a skill that moves the
hand, when the hand has stood still for ``STALL_S``: either way ``actions_done``
counts it and the action source judges the world, as after a classical action (the
monitor repeats an action whose effects are missing, or replans). The same ground action
failing :data:`MAX_TRIES` times in a row stops the run, named; so does a skill that
answers NaN (exit 3, naming the skill and the action).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem

from cake_drake.errors import ExecutionError
from cake_drake.geometric.waypoints import (
    WaypointParams,
    around_base,
    comfortable_yaw,
    nearest_turn,
    transit_height,
    yaw_of,
)
from cake_drake.plugins import DURING, guarded
from cake_drake.policy import spaces
from cake_drake.policy.observations import (
    SkillContext,
    relative_vector,
    skill_context,
    skill_vector,
)
from cake_drake.scenario import ACT_BUDGET_S
from cake_drake.symbolic import GroundAction
from cake_drake.systems.plan_source import MAX_TRIES, ActionCommand, Refusal
from cake_drake.systems.waypoint_ik import (
    WorldIndices,
    declare_reference_ports,
    hold_target,
    reference_target,
)
from cake_drake.world.facts import CENTRED, read_facts
from cake_drake.world.scene import CUBE_SIZE

#: m below the transit height the grasp frame may be when a pick or a place counts as done.
LIFT_TOL = 0.02
#: Control periods an action may take (15 s at 10 Hz) unless the scenario says.
DEFAULT_BUDGET = 150
GRIPPER_MAX = 0.08
#: m/s each finger's command moves at most (the classical layer's close and open:
#: ``Timing.gripper_time`` in :mod:`cake_drake.geometric.trajectory`, 4 cm in 0.2 s).
FINGER_SPEED = 0.2
#: The action spaces a skill may answer in, and how many numbers each answer has.
SKILL_SPACES = {"joint_position": 8, "ee_delta": 7}


#: m: a skill that never sees the arm reads a destination further across as one this far,
#: on the way around the arm's base (:meth:`LearnedSkills._around`).
AROUND = 0.15
#: s: a hand that moves a skill's hand and has stood still this long (the action not done)
#: ends its try, as its budget would (:meth:`LearnedSkills._update`).
STALL_S = 2.0
#: s: a place's hand stopped this long where its cube may be let go (resting on its
#: target, ``_gripper``) lets go, whatever the skill decides.
LET_GO_S = 1.0
#: m: a hand that moved less than this in a control period has stopped; a stopped hand's
#: next move is taken from where it was last sent, at most ``LEAD`` on (``_short``).
STILL = 0.001
LEAD = 0.02
#: m: a hand further across than this from where it goes down to (a pick's cube, or where
#: a place puts its cube) keeps above it by the classical pre-grasp height
#: (``WaypointParams.approach``): it goes down only once over it (:meth:`_over`).
ALIGNED = 0.01
#: m: how far across from the hand's way a cube stands in it: the open fingers' half-span
#: with a finger's width (5 cm) and a cube's half-diagonal (2.8 cm). While crossing, the
#: hand keeps above every such cube by ``approach`` as well (:meth:`LearnedSkills._over`).
REACH = 0.08
#: m: a place's cube is let go only once it is this close above resting on its target
#: (and over its support's top); a decision to open elsewhere is held
#: (:meth:`LearnedSkills._gripper`).
SEATED = 0.01
#: m: fingers this much wider than a cube have let go of it.
RELEASED = 0.004


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

    done: int = 0  # actions ended (their effects held, or their budget ran out)
    working: int = -1  # index of the action under way, -1 when idle
    action: GroundAction | None = None  # the action under way, in the domain's names
    context: SkillContext | None = None
    steps: int = 0  # control periods of the action under way
    tries: int = 0  # ends without effects of the same action, in a row
    last_failed: GroundAction | None = None
    error: str | None = None
    warnings: tuple[str, ...] = ()
    #: Totals for the run's summary: actions ended by their effects, by their budget,
    #: and the skill's control periods.
    succeeded: int = 0
    timed_out: int = 0
    total_steps: int = 0
    #: rad: the yaw, modulo a quarter turn, the hand keeps to through the action under way
    #: (a skill blind to quarter turns; chosen at its first period: :meth:`_wrist_turn`).
    wrist: float | None = None
    #: m: where the hand was measured at the last period (x y z), for :meth:`_short`.
    hand: tuple[float, float, float] | None = None
    #: Control periods in a row the hand has stood still (moved less than ``STILL``), and
    #: the tries of the run ended so (``STALL_S``).
    still: int = 0
    stalled: int = 0

    def __deepcopy__(self, memo):
        return self


class LearnedSkills(LeafSystem):
    """See the module's docstring. ``meaning`` maps the domain's ground action to the
    exercise's names (as ``WaypointIk``'s); ``label`` names the skill in messages."""

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
        #: The skill reads every yaw modulo a quarter turn (a cube's faces are alike):
        #: the hand may then take whichever quarter turn of its answer keeps the wrist
        #: mid-range (:meth:`_wrist_turn`).
        self._free_turns = bool(getattr(skill, "free_quarter_turns", False))
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
            # A hand stood still with its action not done is at a point the skill answers
            # with no move: its try ends there, not at its budget, 13 s of simulated time
            # later (the skill is reset for the next; a skill with no history answers the
            # same from the same place, one with history may not).
            moved = np.linalg.norm(X_WG.translation() - prog.hand) >= STILL
            prog = replace(prog, still=0 if moved else prog.still + 1)
            if prog.still * self.period_s >= STALL_S:
                self._set(state, self._end(replace(prog, stalled=prog.stalled + 1), False))
                return
        observation = self._observe(context, prog.context, cubes, X_WG)
        # Guarded as every plug-in's answer: what it raises, or an answer slower than its
        # budget, stops the run in one line naming the skill.
        raw = guarded(f"skill {self.label!r}", self.skill.act, observation, exit_code=DURING,
                      budget_s=self._budget_s)  # fmt: skip
        size = SKILL_SPACES[self.space]
        try:
            answer = np.asarray(raw, float).reshape(-1)
            shown = np.array2string(answer, precision=3)
        except (TypeError, ValueError):  # not numbers at all
            answer, shown = np.empty(0), repr(raw)
        if answer.shape != (size,) or not np.all(np.isfinite(answer)):
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
        if self.space == "ee_delta":
            low, high = spaces.bounds("ee_delta", {}, None, None)
            move = np.clip(answer, low, high)
            self.counts.clipped += int(not np.array_equal(move, answer))
            if self._free_turns:
                move[5], wrist = self._wrist_turn(prog, cubes, X_WG, move[5], high[5])
                prog = replace(prog, wrist=wrist)
            last = reference_target(self._groups, context)
            sent = self.ik.kin.pose(last).translation()  # where the hand was last sent
            base = self._short(prog, X_WG, sent)
            move[2] = self._over(prog.context, cubes, X_WG, base, move[:3], float(sent[2]))
            q = spaces.ee_target(move[:6], base, self.ik, last, self.counts, down=True)
            prog = replace(prog, hand=tuple(X_WG.translation()))
            target, width = (last if q is None else q), float(move[6]) * GRIPPER_MAX
            stopped = prog.still * self.period_s >= LET_GO_S
            width = self._gripper(prog.context, cubes, X_WG, width, context, stopped)
        else:
            target, width = answer[:7], float(np.clip(answer[7], 0.0, GRIPPER_MAX))
        hold_target(self._groups, context, state, target, self.smooth_s)
        # The fingers' command moves at their speed, as the classical layer's and every
        # demonstrator's does: a decision answered as a step would slam them shut.
        was = context.get_discrete_state(self._groups["finger_state"]).get_value()[0]
        most = FINGER_SPEED * self.period_s
        half = float(np.clip(width / 2, was - most, was + most))
        fingers = np.array([half, half, 0.0, 0.0])
        state.get_mutable_discrete_state(self._groups["finger_state"]).set_value(fingers)
        self._set(state, replace(prog, steps=prog.steps + 1, total_steps=prog.total_steps + 1))

    @staticmethod
    def _short(prog: SkillProgress, X_WG: RigidTransform, sent) -> RigidTransform:
        """Where a move of the hand is taken from: the hand as measured, or, when it has
        stopped (moved less than ``STILL`` since the last period) short of ``sent`` (x y z,
        where it was last sent), that place (at most ``LEAD`` on from the hand). Taken from
        the measured hand alone, a move the controller falls short of by a steady error is
        sent again to the same place: under a 0.5 kg cube the hand held a stack 9 mm across
        from its place, the skill answering the 9 mm period after period. From where it was
        sent, the shortfall adds up, period by period, until the hand moves."""
        if prog.hand is None or np.linalg.norm(X_WG.translation() - prog.hand) >= STILL:
            return X_WG
        short = np.asarray(sent, float) - X_WG.translation()
        far = float(np.linalg.norm(short))
        if far > LEAD:
            short *= LEAD / far
        return RigidTransform(X_WG.rotation(), X_WG.translation() + short)

    def _over(
        self, action: SkillContext, cubes, X_WG, base: RigidTransform, move, sent=None
    ) -> float:
        """The move down or up (m) a hand measured at ``X_WG`` may take this period, of
        ``move`` (dx dy dz) from ``base`` (:meth:`_short`): while it is more than ``ALIGNED``
        across from where it goes down to (the cube a pick takes; for a place, where the
        hand is when its cube rests on its target; half a cube for a put-down), not below
        that point, nor below any other cube within ``REACH`` of its way this period, by
        the classical pre-grasp height (``approach``); a hand already lower goes no lower
        than it is, or than ``sent``, the height it was last sent to, when that is higher
        (under a 0.5 kg cube the hand sags below where it is sent; held where it was
        measured, period after period, it crept down a centimetre every few periods). The
        classical layer goes down only over the cube, from its pre-grasp pose, and crosses
        at the transit height. A skill that cut the corner went down while still 4 cm
        across, its leading finger came down on the top cube of the tower it was to
        unstack and knocked it off (problem_5); set off from the top of a five-cube tower
        it had just stacked on, it went down at once toward a cube on the table and its
        fingers swept the tower's top cube off; a cube carried down toward the table met a
        two-cube tower on the way (eight cubes in tall towers). Further than ``AROUND``
        across (where the skill's own reading of the far target begins, :meth:`_around`),
        the hand keeps to the classical transit height (:func:`transit_height` of every
        cube but the held one), rising to it at most a step a period: a put-down that left
        the home height for a spot beyond an eight-cube tower went down 5 cm a period while
        the tower was still further than ``REACH`` from its way, and once within it, held
        no lower, pushed the tower's second cube 16 mm (ten cubes in tall towers)."""
        hand, z = X_WG.translation(), base.translation()[2]
        dz = float(move[2])
        cube = cubes[action.cube].translation()
        to = cube if action.target is None else action.target + (hand - cube)
        # A put-down's place is a free spot of the table: half a cube from the one planned
        # is as good, and under a 0.5 kg cube the hand stood 1.5 cm short of it, held.
        putting_down = action.target is not None and action.other is None
        across = np.hypot(*(to[:2] - hand[:2]))
        if across <= (CUBE_SIZE / 2 if putting_down else ALIGNED):
            return dz
        if across > AROUND:  # far off: the classical transit height, risen to a step a period
            held = action.cube if action.target is not None else None
            return max(dz, min(transit_height(cubes, held, self._params) - z, spaces.EE_STEP[2]))
        a, b = hand[:2], base.translation()[:2] + np.asarray(move[:2], float)
        floor = to[2]
        for name, X in cubes.items():
            at = X.translation()
            if name != action.cube and _across(at[:2], a, b) <= REACH:
                floor = max(floor, at[2])
        lowest = min(z if sent is None else max(z, sent), floor + self._params.approach)
        return max(dz, lowest - z)

    def _gripper(
        self, action: SkillContext, cubes, X_WG, width: float, context, stopped: bool = False
    ) -> float:
        """The gripper's width this period, of the skill's ``width``: the fingers close only
        around the cube a pick takes, and open only where a place's cube rests. A decision
        to close while the pick's cube is not between the fingers (its centre further
        across than half a cube from the grasp frame, or further up or down than half a
        cube), or to open while the place's cube is in the fingers (its centre within
        ``SEATED`` + half a cube of the grasp frame) and not resting on its target (further
        across than ``CENTRED`` for a stack or half a cube for a put-down, or more than
        ``SEATED`` above it), is held at the fingers' present command. The classical layer
        closes only at the grasp pose and opens only at the place pose; from a home pose
        2 cm above the top of a ten-cube tower, a skill closed its fingers on air at its
        first period and then sat over the cube as if it held it (ten cubes in tall
        towers), and a skill carrying a cube across the table opened 15 cm short of its
        target and dropped it beside another tower (eight cubes in tall towers).

        Out of the fingers (its centre further than ``SEATED`` + half a cube from the grasp
        frame), a pick's cube is approached with the fingers open, whatever the skill
        decides, and a place's cube, let go, is not closed on again: as the classical
        layer's fingers, open from its pre-grasp pose and from its release to its retract.
        Under 0.5 kg cubes a skill that had let go of its cube closed its fingers on air
        while going back up, and the next pick began closed, a start no demonstration
        had: the skill hovered 9 cm over its cube, never opening (``learned_cake``). A
        place's hand ``stopped`` (still for ``LET_GO_S``) where its cube may be let go
        lets go: with a 0.5 kg cube resting 6 mm from its spot on the table, the skill
        answered a millimetre's move the pressed cube did not take, and no release, for
        three tries (``learned_cake``). A stack's cube rests on its target only within
        ``CENTRED`` across of it: under 0.5 kg cubes the hand came down onto the support
        still 5 to 15 mm across, its move answered toward the centre, and the skill
        decided to open there; the monitor found the cube off and had it set down and
        stacked again, and again (``learned_cake``)."""
        was = 2.0 * context.get_discrete_state(self._groups["finger_state"]).get_value()[0]
        cube, hand = cubes[action.cube].translation(), X_WG.translation()
        out = np.linalg.norm(cube - hand) > SEATED + CUBE_SIZE / 2
        if action.target is None:  # a pick: open until its cube is near, close only around it
            if out:
                return GRIPPER_MAX
            off = cube - hand
            around = np.hypot(*off[:2]) <= CUBE_SIZE / 2 and abs(off[2]) <= CUBE_SIZE / 2
            return was if width < was and not around else width
        if out:  # let go, or dropped: the fingers close no further
            return max(width, was)
        off = cube - action.target
        across = CUBE_SIZE / 2 if action.other is None else CENTRED
        rests = np.hypot(*off[:2]) <= across and off[2] <= SEATED
        if rests and stopped:
            return GRIPPER_MAX
        return width if width <= was or rests else was

    def _wrist_turn(self, prog: SkillProgress, cubes, X_WG, dyaw: float, most: float):
        """The turn of the hand this period (at most ``most`` rad) for a skill that reads
        yaws modulo a quarter turn, and the yaw it keeps to: at the action's first period,
        the quarter turn of where the answer ``dyaw`` points that is nearest the
        comfortable yaw over the action's target (the classical layer's choice,
        :func:`cake_drake.geometric.waypoints.comfortable_yaw`); after it, the quarter turn
        of the answer nearest that one. The skill's own answer turns the hand nearest to
        where it is, so, action after action, the wrist wound up to its joint limit (joint
        7 at 2.9 rad on a generated eight-cube problem) and the IK below could not follow
        the next move. Chosen once an action: chosen afresh each period, an answer near
        the half-way yaw between two quarter turns turned the hand to and fro."""
        hand = yaw_of(X_WG)
        wrist = prog.wrist
        if wrist is None:
            action = prog.context
            where = action.target if action.target is not None else cubes[action.cube].translation()
            wrist = comfortable_yaw(where, self._params)
            wrist = nearest_turn(hand + dyaw, wrist)
        goal = nearest_turn(hand + dyaw, wrist)
        return float(np.clip(goal - hand, -most, most)), wrist

    def _observe(self, context, action: SkillContext, cubes, X_WG) -> dict:
        arm = self._arm.Eval(context)
        hand = self._hand.Eval(context)
        skill = skill_vector(action, cubes, X_WG)
        width = hand[0] + hand[1]
        return {
            "observation.state": np.r_[arm[:7], width].astype(np.float32),
            "observation.skill": skill,
            # What a skill that never sees the arm reads: no joint, no absolute height.
            "observation.relative": relative_vector(
                self._clear(action, cubes, self._around(action, skill, X_WG), X_WG, width),
                width,
            ),
        }

    def _clear(self, action: SkillContext, cubes, skill: np.ndarray, X_WG, width: float):
        """``skill`` as a skill that never sees the arm reads it once a place's fingers
        have let go of its cube: the transit height the hand goes back up to is then the
        classical retract's, clear of the cube just placed by ``transit_clearance`` (the
        height :func:`effects_hold` asks for), where the action's own is below it. Stacked
        on the tallest tower, the cube rose above the transit height of the towers as they
        stood before; the skill went back up to that height, read as its own, and sat 4 mm
        under where the action counts as done until its budget ran out (ten cubes in
        tall towers)."""
        if action.target is None or width <= CUBE_SIZE + RELEASED:
            return skill
        cube = cubes[action.cube].translation()
        after = cube[2] + CUBE_SIZE + self._params.transit_clearance - X_WG.translation()[2]
        if after <= skill[12]:
            return skill
        out = skill.copy()
        out[12] = after
        return out

    def _around(self, action: SkillContext, skill: np.ndarray, X_WG) -> np.ndarray:
        """``observation.skill`` as a skill that never sees the arm reads it: a destination
        further across than ``AROUND`` read as the point ``AROUND`` from the hand on the
        way around the arm's base (:func:`cake_drake.geometric.waypoints.around_base`):
        the target, and a cube still to be picked, moved by the same step; a held cube
        stays in the hand. Read as they are, towers on opposite sides of the table led the
        hand straight across, 22 cm from the base, and the arm folded to its elbow's
        limit (a generated ten-cube problem)."""
        hand = X_WG.translation()[:2]
        picking = action.target is None  # the hand goes to the cube; a place's, to its target
        destination = hand + (skill[4:6] if picking else skill[8:10])
        shift = around_base(hand, destination, AROUND) - destination
        if not shift.any():
            return skill
        out = skill.copy()
        out[8:10] += shift
        if picking:
            out[4:6] += shift
        return out

    def observe(self, context) -> dict | None:
        """What the skill reads now about the action under way (None when idle): the
        skill environment's observation between two of this system's updates."""
        prog = self.progress(context)
        if prog.context is None:
            return None
        cubes, X_WG, _ = self._measure(context)
        return self._observe(context, prog.context, cubes, X_WG)

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
        """The action is over: counted done for the action source to judge."""
        tries = 0 if held else (prog.tries + 1 if prog.last_failed == prog.action else 1)
        error = None
        if tries >= MAX_TRIES:
            error = (
                f"skill {self.label!r} did not do {prog.action} in {MAX_TRIES} tries of "
                f"{self.budget} steps each"
            )
            if prog.still * self.period_s >= STALL_S:
                error += f"; the last ended with the hand still for {STALL_S:g} s"
        return replace(
            prog,
            done=prog.done + 1,
            working=-1,
            context=None,
            steps=0,
            tries=tries,
            last_failed=None if held else prog.action,
            error=error,
            succeeded=prog.succeeded + held,
            timed_out=prog.timed_out + (not held),
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


def _across(point, a, b) -> float:
    """How far (m) ``point`` is from the segment ``a``-``b`` (x y)."""
    ab = b - a
    t = float(np.clip(np.dot(point - a, ab) / max(float(np.dot(ab, ab)), 1e-12), 0.0, 1.0))
    return float(np.hypot(*(point - (a + t * ab))))
