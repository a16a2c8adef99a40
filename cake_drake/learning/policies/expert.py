"""The classical cake as a closed-loop teacher: an expert that answers from any state.

A teacher for imitation learning (DAgger, DART) must label the states a learner drifts
into, not only the ones its own demonstration visits. This expert therefore decides at
every step from what it measures, the way the execution monitor
(:class:`cake_drake.systems.monitor.ExecutionMonitor`) closes the classical loop:

1. **Facts.** The cube poses, the grasp frame and the gripper's width become Blocksworld
   facts exactly as the monitor reads them (:func:`cake_drake.world.facts.read_facts`,
   ``holding`` from :func:`~cake_drake.world.facts.held_cube`). A cube off the table or
   out of reach ends the episode; a cube that rests on nothing (falling, tilted) is
   waited for, :data:`REST_WAIT_S` at most.
2. **The plan.** The plan is kept while the measured facts are what its current action
   expects (the triangle-table kernel of that action before its gripper closes or opens,
   the next one's after). Otherwise the expert continues from the latest kernel that
   holds (a dropped cube is picked again) or, when none does, plans again from the
   measured facts with the scenario's planner (a knocked tower is rebuilt).
3. **Motion.** An action's motion is the classical layer's: waypoints from the measured
   poses, IK, quintic moves (:func:`cake_drake.geometric.solve.solve_action`; the place
   refined above its target and corrected at release, as ``WaypointIk`` does), timed from
   the *measured* joints with the speed limits scaled for the policy's rate, so that one
   held step never asks for more than an ``ee_delta`` step allows. The motion's clock
   advances only while the hand keeps up; a hand far off the motion (pushed, or moved by
   someone else) drops it, and the next one starts from where the hand is, first straight
   up to the transit height when the hand is below it. Once the world has been mended
   (cubes may lie anywhere), each motion is checked against the cubes and turned a quarter
   or raised where it would hit one (``solve_action``'s ``avoid_collisions``); a cube
   lying tilted against another is picked by the two faces its tilt leaves vertical.

The answer is in the task's action space: ``joint_position`` (the motion one step ahead),
``ee_delta`` (the move from the measured grasp frame to there, and the gripper) or
``joint_chunk`` (the next ``horizon`` rows). When no plan or motion exists from the
measured state, ``act`` returns ``(None, True)`` and :attr:`ClosedLoopExpert.reason`
says why; when the goal holds it does the same with ``reason`` ``"goal reached"``.
Nothing depends on the clock or on earlier episodes: a seed gives the same answers.

    expert = make()
    expert.reset(env.unwrapped.policy_task, seed)
    answer = expert.act(obs)  # an action, or (None, True): then expert.reason
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from cake_drake.errors import CakeDrakeError
from cake_drake.geometric.collisions import CollisionChecker
from cake_drake.geometric.ik import Kinematics, make_solver
from cake_drake.geometric.solve import refine_action, release_action, solve_action
from cake_drake.geometric.trajectory import (
    GRIPPER_CLOSED,
    GRIPPER_OPEN,
    JointTrajectory,
    Segment,
    Timing,
)
from cake_drake.geometric.waypoints import (
    PLACE_ACTIONS,
    WaypointParams,
    WorldView,
    gripper_down,
)
from cake_drake.pipeline import (
    PLANNER_REGISTRY,
    Checked,
    call_planner,
    check_table_room,
    get_plan,
)
from cake_drake.plugins import resolve
from cake_drake.policy.observations import (
    SKILL_SIZE,
    SkillContext,
    ground_row,
    skill_context,
    skill_vector,
)
from cake_drake.policy.spaces import EE_STEP, GRIPPER_MAX
from cake_drake.symbolic import (
    DEFAULT_PLANNER,
    GroundAction,
    Plan,
    Problem,
    fact_str,
    validate_plan,
)
from cake_drake.symbolic.grounding import apply_action
from cake_drake.symbolic.kernels import kernels, latest_kernel
from cake_drake.symbolic.roles import PICK, PLACE, blocksworld_roles, blocksworld_view
from cake_drake.world.facts import CENTRED, lost_cubes, read_facts, stack_offsets
from cake_drake.world.scene import CUBE_SIZE

#: s a world that does not read as facts (a cube falling, rolling or tilted) is waited for.
REST_WAIT_S = 1.5
#: The hand keeps up with its motion when this close (m, rad) to where the motion is at
#: the last target or up to :data:`LAG_STEPS` steps before it: the motion's clock advances.
TRACK_TOL = (0.025, 0.1)
#: The hand is at a stop of its motion (where the fingers close or open) when this close
#: (m, rad), or when it is still within :data:`TRACK_TOL`.
ARRIVE_TOL = (0.004, 0.03)
#: Steps the hand may trail its targets (a held target takes the controller a while).
LAG_STEPS = 2
#: The hand is off its motion when this far (m, rad): the motion is dropped and planned
#: again from where the hand is.
OFF_TRACK = (0.05, 0.3)
#: s the motion's clock may wait for the hand before the motion is planned again.
STALL_S = 3.0
#: Motions the hand does not follow, one after the other, before the expert gives up.
MAX_STALLS = 3
#: m the hand may move between two steps and count as still (a release measures it still).
STILL = 0.001
#: Extra steps (at most) a gripper change is waited for before the facts must show it.
GRIP_WAIT_S = 0.5
#: Replans, repeated actions and dropped motions an episode may take before it gives up.
MAX_REPAIRS = 20
#: Speed limits' scale at 10 Hz: a 10 Hz step then moves the hand less than ``EE_STEP``.
SLOW_AT_10HZ = 0.35


@dataclass(frozen=True)
class Measured:
    """What the expert reads of an observation: joints, gripper, grasp frame, cubes."""

    q: np.ndarray  # 7 arm joints (rad)
    width: float  # between the fingers (m)
    X_WG: RigidTransform  # the grasp frame
    cubes: dict[str, RigidTransform]


def _pose(row) -> RigidTransform:
    row = np.asarray(row, float)
    w = row[3:7] / np.linalg.norm(row[3:7])
    return RigidTransform(RotationMatrix(Quaternion(w)), row[:3])


def measured(observation: Mapping, cubes: Sequence[str]) -> Measured:
    """The keys the expert reads, from the policy slot's observation
    (``observation.state``, ``observation.ee_pose``, ``observation.cubes``) or from
    ``CakeDrake/Stack-v0``'s (``state``: q 7, width, q-dot 7, grasp pose 7; ``cubes``)."""
    if "observation.state" in observation:
        state = np.asarray(observation["observation.state"], float)
        ee = observation["observation.ee_pose"]
        rows = observation["observation.cubes"]
    else:
        state = np.asarray(observation["state"], float)
        ee = state[15:22]
        rows = observation["cubes"]
    rows = np.asarray(rows, float).reshape(-1, 7)
    poses = {name: _pose(rows[k]) for k, name in enumerate(cubes)}
    return Measured(state[:7].copy(), float(state[7]), _pose(ee), poses)


def _angle(R1: RotationMatrix, R2: RotationMatrix) -> float:
    return float(R1.multiply(R2.inverse()).ToAngleAxis().angle())


@dataclass
class _Action:
    """The action being done: its motion from the measured state, and the motion's clock."""

    pos: int  # index in the plan
    action: GroundAction  # in the domain's names
    meaning: GroundAction  # in the exercise's (pick-up, unstack, put-down, stack)
    trajectory: JointTrajectory  # local clock: 0 is when the action started
    params: WaypointParams
    pending: str | None = None  # "transport": refine there; "place": release there
    X_place: RigidTransform | None = None
    tau: float = 0.0  # the motion's time the hand was last sent to
    waited: int = 0  # steps the clock has waited for the hand
    #: What a learned skill would be told of this action (observation.skill's targets).
    skill: SkillContext | None = None

    def expects(self, tau: float, grace: float) -> tuple[int, ...]:
        """Kernel indices the world may be at: this action's before its gripper change,
        the next one's after it, either while it is under way."""
        changes = [s for s in self.trajectory.segments if s.gripper != s.gripper0]
        if not changes or tau < changes[-1].t0:
            return (self.pos,)
        if tau <= changes[-1].end + grace:
            return (self.pos, self.pos + 1)
        return (self.pos + 1,)


@dataclass
class ClosedLoopExpert:
    """See the module's docstring. ``slow`` scales the classical speed limits at 10 Hz
    (scaled with the rate: twice the rate, twice the speed, up to the limits);
    ``max_repairs`` bounds the replans, repeats and dropped motions of one episode (None:
    no bound, as DAgger's labeller: a learner in control drags the hand off every motion,
    and a teacher that gave up would label none of the states it drifts into; nor does
    it then give up on motions the hand does not follow, ``MAX_STALLS``)."""

    slow: float = SLOW_AT_10HZ
    max_repairs: int | None = MAX_REPAIRS
    #: Why the last episode ended (None while it runs): "goal reached" or what stopped it.
    reason: str | None = None
    #: What the expert decided, one dict per decision (replans, repeats, dropped motions).
    events: list[dict] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.kin = Kinematics()
        self._collisions = None  # the collision checker, made when first needed

    # --- the episode --------------------------------------------------------------------

    def reset(self, task, seed: int) -> None:
        """Plan ``task.problem`` as the run did and prepare the classical layer."""
        scenario = task.scenario
        self.problem: Problem = task.problem
        self.cubes = tuple(task.cubes)
        self.space, self.dt = task.action_space, 1.0 / task.rate_hz
        options = task.options or {}
        self.horizon = int(options.get("horizon", 10))
        self.execute = int(options.get("execute", self.horizon))
        self.roles = blocksworld_roles(self.problem.domain)
        self.goal = blocksworld_view(self.problem).goal  # in the canonical names
        vocabulary = set(self.roles.vocabulary.as_dict().values())
        self.static = frozenset(f for f in self.problem.init if f[0] not in vocabulary)
        t = scenario.task
        spec = t.planner if not t.plan else DEFAULT_PLANNER  # a plan file: replan with it
        self.planner = resolve(
            spec, PLANNER_REGISTRY, "planner", budget=lambda problem, limit: limit
        )
        self.time_limit = t.time_limit
        planner = None if t.plan else self.planner
        plan = get_plan(Checked(scenario, self.problem, planner, None))
        self._set_plan(tuple(plan.actions))
        world = scenario.world
        needed = _table_room(self.problem, self.plan, len(world.slots))
        # The slots the run laid the cubes on first, then the rest of the table's.
        own = tuple(world.slots_for(needed))
        self.slots = own + tuple(s for s in world.slots if all(math.dist(s, o) > 0.05 for o in own))
        self.params: WaypointParams = copy.deepcopy(scenario.motion.waypoints)
        scale = min(1.0, self.slow * task.rate_hz / 10.0)
        base: Timing = scenario.motion.timing
        self.timing = dataclasses.replace(
            base,
            velocity_fraction=base.velocity_fraction * scale,
            acceleration_fraction=base.acceleration_fraction * scale,
            gentle_phases=list(base.gentle_phases),
        )
        self.ik = make_solver(scenario.motion.ik, self.kin, seed=scenario.seed)
        self.limits = self.kin.limits
        self.reason, self.events = None, []
        self.repairs = self.replans = 0
        self.current: _Action | None = None
        self.next = 0  # the plan action after the last one finished
        self.forced = 0  # the plan's first actions are a re-placement, done in order
        self.steps = 0
        self._waiting_since: int | None = None
        self._last: tuple[np.ndarray, float] | None = None
        self._previous_p: np.ndarray | None = None
        self._still = False
        self._previous_cubes: dict[str, RigidTransform] | None = None
        self.stranded: set[str] = set()  # cubes taken as on the table (see act)
        self._pending_pickups: tuple[str, ...] = ()
        self._stalls = 0  # motions dropped in a row because the hand did not follow
        self._measured: Measured | None = None
        if self._collisions is not None and self._collisions.blocks != self.cubes:
            self._collisions = None  # kept across episodes of the same cubes

    def _set_plan(self, actions: tuple[GroundAction, ...]) -> None:
        self.plan = actions
        self.kernels = kernels(self.problem, actions)

    def act(self, observation: Mapping):
        """One step: read the world, keep or mend the plan, answer from where the hand is.

        An action, or ``(None, True)`` when the episode is over for the expert: then
        :attr:`reason` says why (``"goal reached"``, or what leaves it without a plan)."""
        try:
            return self._act(observation)
        except CakeDrakeError as e:  # what the layers below refuse ends the episode, named
            return self._end(f"no plan from the measured state: {e}")

    def _act(self, observation: Mapping):
        if self.reason is not None:
            return None, True
        m = self._measured = measured(observation, self.cubes)
        step, self.steps = (
            self.steps,
            self.steps + (self.execute if self.space == "joint_chunk" else 1),
        )
        still = self._still = self._previous_p is not None and bool(
            np.linalg.norm(m.X_WG.translation() - self._previous_p) < STILL
        )
        self._previous_p = m.X_WG.translation()
        self._previous_cubes, previous = m.cubes, self._previous_cubes
        if self._last is None:
            self._last = (m.q, m.width)
        lost = lost_cubes(m.cubes)
        if lost:
            return self._end(f"no plan from the measured state: {lost[0]}")
        reading = read_facts(m.cubes, X_WG=m.X_WG, finger_opening=m.width / 2)
        canonical = self._stranded_facts(reading.facts, m)
        if canonical is None:  # falling or rolling: wait for the world to come to rest
            since = step if self._waiting_since is None else self._waiting_since
            self._waiting_since = since
            if (step - since) * self.dt < REST_WAIT_S:
                return self._hold(m)
            stuck = self._strandable(reading.facts, m, previous)
            problems = "; ".join(reading.problems)
            if stuck is None:
                return self._end(f"no plan from the measured state: {reading.problems[0]}")
            # Still, but on nothing the facts can name (across two cubes, on a corner):
            # taken as standing on the table, it is picked up and put down on a slot.
            self.stranded |= stuck
            self.current = None
            why = f"{', '.join(sorted(stuck))} still on nothing the facts name ({problems})"
            if not self._repair("stranded", why, step):
                return None, True
            self.forced, self.next = 0, 0
            # The highest first: a cube leaning on another is lifted off it before that one.
            self._pending_pickups = tuple(
                sorted(stuck, key=lambda c: (-m.cubes[c].translation()[2], c))
            )
            canonical = self._stranded_facts(reading.facts, m)
        self._waiting_since = None
        facts = self.roles.from_canonical(canonical) | self.static
        a = self.current
        if a is not None:
            why = self._off(a, m, facts)
            if why is not None:
                self._stalls = self._stalls + 1 if "not followed" in why else 0
                if self._stalls >= MAX_STALLS and self.max_repairs is not None:
                    return self._end(f"no motion for {a.action}: the hand is held back")
                self._repair("dropped", why, step)
                a = self.current = None
            elif a.tau >= a.trajectory.end_time - 1e-9 and self._near(a, m, a.tau, lag=0):
                if a.pending is not None:
                    if not still:
                        return self._answer(a, m, advance=False)
                    try:
                        self._extend(a, m)
                    except CakeDrakeError as e:
                        return self._end(f"no motion for {a.action}: {e}")
                else:
                    self.next, self._stalls = a.pos + 1, 0
                    a = self.current = None
        if a is None:
            i = None if self.reason is not None else self._choose(facts, canonical, m, step)
            if i is None:
                return None, True
            if i == len(self.plan):
                return self._end("goal reached")
            try:
                a = self.current = self._start(i, m, canonical)
            except CakeDrakeError as e:
                return self._end(f"no motion for {self.plan[i]}: {e}")
        return self._answer(a, m, advance=True)

    def skill_observation(self) -> tuple[np.ndarray, np.ndarray]:
        """What a learned skill would have read at the last step (``observation.skill``)
        and which ground action was under way (``ground_action``): zeros and -1 while no
        action is (waiting, or the episode over). Read by the recording, per frame."""
        a, m = self.current, self._measured
        if a is None or a.skill is None or m is None:
            return np.zeros(SKILL_SIZE, np.float32), ground_row(None, self.cubes, -1)
        return skill_vector(a.skill, m.cubes, m.X_WG), ground_row(a.skill, self.cubes, a.pos)

    # --- deciding -----------------------------------------------------------------------

    def _off(self, a: _Action, m: Measured, facts) -> str | None:
        """Why the action's motion no longer fits the world, or None when it does."""
        expected = [j for j in a.expects(a.tau, GRIP_WAIT_S) if j < len(self.kernels)]
        if not any(self.kernels[j] <= facts for j in expected):
            missing = sorted(self.kernels[expected[-1]] - facts)
            return (
                f"{a.action}: the world is not what it needs ({fact_str(missing[0])} is not true)"
            )
        dp, dr = self._behind(a, m, a.tau)
        if dp > OFF_TRACK[0] or dr > OFF_TRACK[1]:
            return f"{a.action}: the hand is {dp * 100:.0f} cm off its motion"
        if a.waited * self.dt > STALL_S:
            return f"{a.action}: the hand has not followed its motion for {STALL_S:g} s"
        return None

    def _choose(self, facts, canonical, m: Measured, step: int) -> int | None:
        """The plan action to do next, from the measured facts: the next one of a
        re-placement under way, else the latest whose kernel holds (a cube stacked too
        far off the one below is set down again first); planned again when none holds.
        None when the episode ends (:attr:`reason`)."""
        if self.next < self.forced and self.kernels[self.next] <= facts:
            return self.next
        self.forced = 0
        # A stranded cube that reads as resting on something again (the one it leaned on
        # was lifted off, a leaning tower came upright) is the planner's, as any other.
        self._pending_pickups = tuple(c for c in self._pending_pickups if c in self.stranded)
        if self._pending_pickups and ("arm-empty",) in canonical:
            cube, self._pending_pickups = self._pending_pickups[0], self._pending_pickups[1:]
            last = (self.roles.action(PICK, cube), self.roles.action(PLACE, cube))
            return self._forced(self.roles.unpile(cube, canonical) + last, facts)
        loose = self._loose(canonical, m.cubes)
        if loose and ("arm-empty",) in canonical:
            if not self._repair("re-place", f"{loose[0][1]} stands off {loose[0][2]}", step):
                return None
            return self._forced(self._re_place(loose[0], canonical), facts)
        i = latest_kernel(self.kernels, facts)
        if i is None:
            if not self._repair("replan", "no kernel of the plan holds", step):
                return None
            rest = self._plan_from(facts)
            if rest is None:
                return None
            self._set_plan(rest)
            self.events[-1]["new_plan"] = [str(a) for a in rest]
            i = latest_kernel(self.kernels, facts)
        if i is not None and i < self.next:
            self.events.append({"step": step, "kind": "repeat", "why": str(self.plan[i])})
        self.next = i
        return i

    def _forced(self, prefix: tuple[GroundAction, ...], facts) -> int | None:
        """A plan of ``prefix``, done in order, then the planner's from where it leads."""
        state = dataclasses.replace(self.problem, init=frozenset(facts))
        for action in prefix:
            state = dataclasses.replace(state, init=apply_action(state, state.init, action))
        rest = self._plan_from(state.init)
        if rest is None:
            return None
        self._set_plan(prefix + rest)
        self.events[-1]["new_plan"] = [str(a) for a in self.plan]
        self.forced, self.next = len(prefix), 0
        return 0

    def _located(self, canonical) -> set[str]:
        return {f[1] for f in canonical if f[0] in ("on", "on-table", "holding")}

    def _stranded_facts(self, canonical, m: Measured):
        """The facts read, with each stranded cube (see :meth:`act`) on the table and clear
        when nothing is on it; None while another cube cannot be read."""
        unread = set(self.cubes) - self._located(canonical)
        self.stranded &= unread  # one that reads again is no longer stranded
        if unread - self.stranded:
            return None
        under = {f[2] for f in canonical if f[0] == "on"}
        extra = {("on-table", c) for c in self.stranded}
        extra |= {("clear", c) for c in self.stranded if c not in under}
        return frozenset(canonical) | extra

    def _strandable(self, canonical, m: Measured, before) -> set[str] | None:
        """The cubes that read as nothing (across two cubes, or tilted against another) but
        stand still, if all do. A tilted one is picked by the two faces its tilt leaves
        vertical (:func:`cake_drake.geometric.waypoints.grasp_yaw`) and falls flat where it
        is set down."""
        unread = set(self.cubes) - self._located(canonical) - self.stranded
        before = before or {}
        for c in unread:
            X = m.cubes[c]
            moved = np.linalg.norm(X.translation() - before[c].translation()) if c in before else 1
            if moved > STILL:
                return None
        return unread

    def _loose(self, canonical, cubes: Mapping[str, RigidTransform]) -> list[tuple]:
        """The goal's ``on`` facts measured true with the upper cube farther off the lower
        than the success test allows (four fifths of it, for a margin), lowest first."""
        offsets = stack_offsets(cubes, canonical)
        loose = [f for f in self.goal & canonical if f[0] == "on" and offsets[f[1]] > CENTRED]
        return sorted(loose, key=lambda f: cubes[f[1]].translation()[2])

    def _re_place(self, fact: tuple, canonical) -> tuple[GroundAction, ...]:
        """Actions that set ``fact``'s upper cube down again on the lower."""
        cube, support = fact[1], fact[2]
        last = (self.roles.action(PICK, cube, support), self.roles.action(PLACE, cube, support))
        return self.roles.unpile(cube, canonical) + last

    def _plan_from(self, facts) -> tuple[GroundAction, ...] | None:
        """The planner's plan from ``facts`` to the goal; None (and :attr:`reason`) if none."""
        problem = dataclasses.replace(self.problem, init=frozenset(facts))
        try:
            plan: Plan = call_planner(self.planner, "planner", problem, self.time_limit)
            check = validate_plan(problem, plan.actions)
            if not check.ok:
                raise CakeDrakeError(check.message)
        except CakeDrakeError as e:
            self._end(f"no plan from the measured facts ({e})")
            return None
        self.replans += 1
        return tuple(plan.actions)

    def _repair(self, kind: str, why: str, step: int) -> bool:
        self.events.append({"step": step, "kind": kind, "why": why})
        self.repairs += 1
        if self.max_repairs is not None and self.repairs > self.max_repairs:
            self._end(f"gave up after {self.max_repairs} repairs; the last: {why}")
            return False
        return True

    def _end(self, reason: str):
        self.reason, self.current = reason, None
        return None, True

    # --- motion -------------------------------------------------------------------------

    def _world(self, m: Measured) -> WorldView:
        return WorldView(m.cubes, m.X_WG, None, self.slots)

    def _start(self, i: int, m: Measured, canonical_facts) -> _Action:
        """The motion of plan action ``i`` from the measured state (first straight up to the
        transit height when the hand is below it)."""
        action = self.plan[i]
        meaning = self.roles.classify(action).canonical()
        held = next((f[1] for f in canonical_facts if f[0] == "holding"), None)
        gripper = GRIPPER_CLOSED if held is not None else GRIPPER_OPEN
        # From the last target when the hand is there (the moves join up), else from the
        # measured joints.
        q0 = np.asarray(m.q, float)
        if self._last is not None and self._last_fits(m):
            q0 = np.asarray(self._last[0], float)
        first = Segment(0.0, self.dt, q0, q0, 0, i, gripper, gripper)
        traj = JointTrajectory(q0, self.limits, 0.0, [first], [0.0])
        tops = [X.translation()[2] + CUBE_SIZE / 2 for n, X in m.cubes.items() if n != held]
        z_transit = max(tops, default=0.0) + CUBE_SIZE / 2 + self.params.transit_clearance
        p = m.X_WG.translation()
        if p[2] < z_transit - 0.02:
            yaw = float(RollPitchYaw(m.X_WG.rotation()).yaw_angle())
            X_up = RigidTransform(gripper_down(yaw), [p[0], p[1], z_transit])
            q_up = self.ik.solve(X_up, q0)
            if q_up is not None:
                traj.move(q_up, "retract", i, self.timing)
        # Once the world has been mended, cubes may lie anywhere, close to where the hand
        # goes: the motion is then checked against them, turned a quarter or raised where
        # it would hit one (an undisturbed episode's cubes stand apart on the table's slots).
        checker = self._checker() if self.repairs else None
        motion = solve_action(
            meaning, i, self._world(m), self.ik, traj, self.timing, self.params,
            checker=checker, avoid_collisions=checker is not None, refine=True,
        )  # fmt: skip
        pending = motion.pending_after if meaning.name in PLACE_ACTIONS else None
        skill = skill_context(meaning, m.cubes, self.slots, self.params)
        return _Action(i, action, meaning, traj, motion.params, pending, skill=skill)

    def _checker(self):
        """The geometric layer's collision checker among this episode's cubes (made once)."""
        if self._collisions is None:
            self._collisions = CollisionChecker(self.cubes)
        return self._collisions

    def _extend(self, a: _Action, m: Measured) -> None:
        """Above the target: the move down, planned from the poses measured now; at the
        place pose: the release, corrected by the hand's measured offset (as ``WaypointIk``)."""
        traj = a.trajectory
        traj.resume_at(a.tau, a.pending, a.pos)
        world = self._world(m)
        if a.pending == "transport":
            motion = refine_action(a.meaning, a.pos, world, self.ik, traj, self.timing, a.params)
            a.pending, a.X_place = "place", motion.waypoints[0].X_WG
        else:
            release_action(a.meaning, a.pos, world, self.ik, traj, self.timing, a.params, a.X_place)
            a.pending = None

    def _last_fits(self, m: Measured) -> bool:
        X = self.kin.pose(self._last[0])
        dp = float(np.linalg.norm(X.translation() - m.X_WG.translation()))
        return dp < TRACK_TOL[0] and _angle(X.rotation(), m.X_WG.rotation()) < TRACK_TOL[1]

    def _behind(self, a: _Action, m: Measured, tau: float, lag: int = LAG_STEPS):
        """(m, rad): how far the hand is from the motion at ``tau`` or up to ``lag`` steps
        before it, whichever is nearest."""
        best = (math.inf, math.inf)
        for k in range(lag + 1):
            X = self.kin.pose(a.trajectory.at(max(tau - k * self.dt, 0.0))[0])
            dp = float(np.linalg.norm(X.translation() - m.X_WG.translation()))
            best = min(best, (dp, _angle(X.rotation(), m.X_WG.rotation())))
        return best

    def _near(self, a: _Action, m: Measured, tau: float, lag: int = LAG_STEPS) -> bool:
        dp, dr = self._behind(a, m, tau, lag)
        return dp < TRACK_TOL[0] and dr < TRACK_TOL[1]

    @staticmethod
    def _stop_after(a: _Action, tau: float) -> float | None:
        """When the motion next stands still, from ``tau`` on (a settle, the fingers closing
        or opening), if it does."""
        stops = [s.t0 for s in a.trajectory.segments if not s.moves and s.t0 > tau - 1e-9]
        return min(stops, default=None)

    def _arrived(self, a: _Action, m: Measured, tau: float) -> bool:
        """Whether the hand is where the motion is at ``tau``: within :data:`ARRIVE_TOL`,
        or still and within :data:`TRACK_TOL` (a hand held off by a cube)."""
        dp, dr = self._behind(a, m, tau, lag=0)
        if dp < ARRIVE_TOL[0] and dr < ARRIVE_TOL[1]:
            return True
        return self._still and dp < TRACK_TOL[0] and dr < TRACK_TOL[1]

    def _answer(self, a: _Action, m: Measured, advance: bool):
        """The action that sends the hand along the motion: the clock moves on when the
        hand is where it was last sent, else the same target is sent again."""
        end = a.trajectory.end_time
        rows = self.horizon if self.space == "joint_chunk" else 1
        moves = self.execute if self.space == "joint_chunk" else 1
        if advance and self._near(a, m, a.tau):
            start, a.waited = a.tau, 0
            target = min(a.tau + moves * self.dt, end)
            stop = self._stop_after(a, a.tau)
            if stop is not None and target > stop - 1e-9 and not self._arrived(a, m, stop):
                target = stop  # the fingers close or open where the hand is, not on its way
            a.tau = target
            if target <= start + 1e-9:
                start, a.waited = a.tau - self.dt, a.waited + 1
        else:
            start, a.waited = a.tau - self.dt, a.waited + 1
        refs = [a.trajectory.at(min(start + k * self.dt, end)) for k in range(1, rows + 1)]
        targets = [(r[0], 2 * r[3]) for r in refs]
        self._last = targets[min(moves, rows) - 1]
        return self._command(targets, m)

    def _hold(self, m: Measured):
        return self._command([self._last] * self.horizon, m)

    def _command(self, targets: list[tuple[np.ndarray, float]], m: Measured) -> np.ndarray:
        if self.space == "joint_chunk":
            return np.array([[*q, w] for q, w in targets[: self.horizon]])
        q, width = targets[0]
        if self.space == "joint_position":
            return np.r_[q, width]
        X = self.kin.pose(q)
        d_rot = X.rotation().multiply(m.X_WG.rotation().inverse())
        delta = np.r_[X.translation() - m.X_WG.translation(), RollPitchYaw(d_rot).vector()]
        return np.r_[np.clip(delta, -EE_STEP, EE_STEP), min(width / GRIPPER_MAX, 1.0)]


def _table_room(problem: Problem, actions, slots: int) -> int:
    """How many table slots the plan needs at once (at most ``slots``)."""
    try:
        return check_table_room(problem, actions, slots)
    except CakeDrakeError:
        return slots


def make(**options) -> ClosedLoopExpert:
    """The plug-in's factory: ``reference: !Policy {factory: cake_drake.learning.expert:make}``."""
    return ClosedLoopExpert(**options)


__all__ = ["ClosedLoopExpert", "Measured", "lost_cubes", "make", "measured"]
