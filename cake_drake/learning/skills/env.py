"""``CakeDrake/Skill-v0``: one ground action of a learned skill is an episode.

Reinforcement learning on whole Blocksworld episodes (``CakeDrake/Stack-v0``) pays for
hundreds of steps before a place is judged; a residual for the last millimetres of a
place needs only the place. Here an episode is **one ground action** of the learned
middle, with the skill's own observation and action, in the same Diagram a run with
``motion.skills`` builds:

- ``reset(seed=...)`` draws a problem as a learning task does (``blocks`` cubes, ``tall``
  towers, a ``placement`` jitter, cubes of ``cube_mass_range_kg``, the task's
  ``controller``), plans it with ``planner`` (the learned planner unless told: a
  hundredth of a second where an optimal search of eight cubes takes seconds, and its
  plans as short), and lets the **lead skill** (the
  checkpoint ``skill``, as under the planner in a run) do the plan's actions until one of
  the ``actions`` kinds starts at or after an index drawn among the plan's first
  ``horizon`` actions: the start is a state that learned runs visit, at the heights the
  problems' towers have. The chosen action's first
  control period is the lead's too; the episode begins one period into it.
- the observation is what the skill reads (``observation.relative``, 14 numbers, for a
  skill that never sees the arm; ``observation.state`` and ``observation.skill``, 21, for
  one that reads the joints); the action is what it answers (``ee_delta``, 7 numbers, or
  ``joint_position``, 8), held for one control period.
- the episode ends (``terminated``) when the action does: its effects hold in the
  measured world (``info["is_success"]``), a cube leaves the table, or the skill system
  gives it up after its budget of ``budget`` periods (``truncated``).
- the reward weighs the terms of :mod:`cake_drake.learning.envs.rewards` (a ``reward``
  mapping, :class:`cake_drake.scenario.Reward`'s names) read for this one action:
  ``goal`` and ``success`` 1 at the step its effects hold (``success`` only if a placed
  cube rests within 5 mm of its target), ``reach`` the hand's nearness to the action's
  target (the cube for a pick, the place for a place), ``lift`` a picked cube raised (1
  from one cube's height), ``place`` a held or placed cube's horizontal alignment over
  its target (1 centred, 0 from 10 mm), ``step`` 1 a step, ``lost`` 1 when a cube leaves
  the table. ``info["offset_mm"]`` is a place's horizontal offset at its end.

The lead runs in the same simulation, so a start costs the simulated seconds of the
actions before it; a lead that gives the run up before the chosen action (three failed
tries), or takes more than ``LEAD_PERIODS`` control periods an action to reach it, is a
draw thrown away, and ``reset`` draws again (at most ``MAX_DRAWS`` times): the starts
are those of the lead's runs that go well.

With ``starts`` (a start pool, :mod:`cake_drake.learning.skills.starts`; ``python -m
cake_drake.record SPEC --starts FILE`` writes one, :meth:`SkillEnv.start` gives the
current episode's), ``reset`` draws one of the pool's starts and puts the Diagram's
state back there: nothing is replayed, and the episode is the one the replayed start
gave, number for number. The Diagrams of the last ``BUILT`` problems stay built.

    import gymnasium
    env = gymnasium.make("cake_drake.gym:CakeDrake/Skill-v0", blocks=(3, 6))
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

import gymnasium
import numpy as np
from gymnasium import spaces as gs
from pydrake.systems.analysis import InitializeParams, Simulator

from cake_drake.diagram import build_diagram
from cake_drake.errors import ExecutionError, InputError
from cake_drake.learning.envs import rewards
from cake_drake.learning.envs.env import _blocks, set_world
from cake_drake.learning.skills import starts as start_pool
from cake_drake.paths import MODELS_DIR, resolve_path
from cake_drake.pipeline import check, plan_and_layout
from cake_drake.policy import spaces
from cake_drake.policy.observations import RELATIVE_SIZE, SKILL_SIZE
from cake_drake.scenario import Generate, Reward, Scenario
from cake_drake.symbolic.roles import blocksworld_roles, blocksworld_view
from cake_drake.systems.skills import DEFAULT_BUDGET, SKILL_SPACES
from cake_drake.world.facts import STACK_TOL
from cake_drake.world.scene import CUBE_SIZE, set_world_parameters

#: The skill a skill environment leads with unless told: the shipped one that never sees
#: the arm.
DEFAULT_SKILL = MODELS_DIR / "policies" / "skills"
#: The kinds of ground action an episode may be (the exercise's names).
ACTION_KINDS = ("pick-up", "unstack", "put-down", "stack")
PLACES = ("put-down", "stack")
#: Draws of a start ``reset`` makes before it gives up (each a problem and an index).
MAX_DRAWS = 20
#: Control periods the lead may take, on average, for each action before the chosen one
#: (a pick or a place of the lead's takes 40 to 50): past them, the draw is given up.
LEAD_PERIODS = 80
#: The Diagrams of a start pool's problems an environment keeps built, the most recently
#: restored (about 16 MB each with up to eight cubes): a pool's problems are few, so
#: most resets build nothing.
BUILT = 64
#: A cube this far below the table's top has left the table.
LOST_Z = -0.05


class HeldSkill:
    """The skill the Diagram asks: the lead's answers until the episode's action has
    begun, then the action the environment was given."""

    def __init__(self, lead) -> None:
        self.lead = lead
        self.action_space = getattr(lead, "action_space", "joint_position")
        # The actions given are executed as the lead's would be (the wrist's quarter turn).
        self.free_quarter_turns = getattr(lead, "free_quarter_turns", False)
        self.action = None  # set by step(); None: the lead answers
        self.label = "the action given to CakeDrake/Skill-v0's step()"

    def reset(self) -> None:
        self.lead.reset()

    def act(self, observation):
        if self.action is None:
            return self.lead.act(observation)
        return self.action


def _kinds(actions) -> tuple[str, ...]:
    if isinstance(actions, str):
        actions = {"places": PLACES, "picks": ("pick-up", "unstack"), "all": ACTION_KINDS}.get(
            actions, (actions,)
        )
    kinds = tuple(actions)
    bad = [a for a in kinds if a not in ACTION_KINDS]
    if not kinds or bad:
        raise InputError(
            f"actions = {actions!r:.60}: the kinds of action an episode may be, from "
            f"{', '.join(ACTION_KINDS)} (or places, picks, all)"
        )
    return kinds


#: Why a draw gave no start, as the message says it.
NO_START = {
    "goal": "held their goal at the start",
    "kinds": "had no {kinds} action among the plan's first {horizon}",
    "lead": "where the lead skill {skill} gave the run up before the chosen action",
}


class SkillEnv(gymnasium.Env):
    """See the module's docstring."""

    metadata = {"render_modes": [], "render_fps": 10}

    def __init__(
        self,
        skill: str = str(DEFAULT_SKILL),
        blocks: int | tuple[int, int] = (3, 8),
        tall: bool = False,
        actions: str | Sequence[str] = "places",
        placement: tuple[float, float] = (0.02, 20.0),
        cube_mass_range_kg: Sequence[float] = (),
        controller=None,
        reward: Mapping | None = None,
        budget: int = DEFAULT_BUDGET,
        rate_hz: float = 10.0,
        time_step: float = 0.01,
        planner: str = "learned",
        horizon: int = 6,
        starts: str = "",
    ) -> None:
        from cake_drake.learning.skills import checkpoints as skills

        self.blocks, self.kinds = _blocks(blocks), _kinds(actions)
        if not isinstance(tall, bool):
            raise InputError(f"tall = {tall!r:.40}: true or false")
        if self.blocks[1] < 2:
            raise InputError(
                f"blocks = {blocks!r:.24}: every problem of one cube holds its goal at its "
                "start, so no episode could start; give 2 blocks or more"
            )
        whole = isinstance(budget, int | np.integer) and not isinstance(budget, bool)
        if not (whole and 1 <= budget <= 10_000):
            raise InputError(f"budget = {budget!r:.24}: control periods an action may take, "
                             "a whole number from 1 to 10000")  # fmt: skip
        self.tall, self.budget, self.rate_hz, self.time_step = tall, int(budget), rate_hz, time_step
        self.placement, self.cube_mass_range_kg, self.controller = (
            placement, cube_mass_range_kg, controller,
        )  # fmt: skip
        self.planner = planner
        if not (isinstance(horizon, int) and not isinstance(horizon, bool) and horizon >= 1):
            raise InputError(f"horizon = {horizon!r:.24}: the plan's first actions an episode "
                             "may start at, a whole number from 1")  # fmt: skip
        self.horizon = horizon
        self.reward = rewards.check_reward(Reward() if reward is None else reward, "reward")
        self.skill_path = str(resolve_path(skill))
        skills.check_folder(resolve_path(skill))  # one line for a folder that is no skill
        self.relative = skills._relative(resolve_path(skill))
        self._lead = skills.make(self.skill_path)
        space = getattr(self._lead, "action_space", "joint_position")
        self.control_mode = space
        size = RELATIVE_SIZE if self.relative else 8 + SKILL_SIZE
        self.observation_space = gs.Box(-np.inf, np.inf, (size,), np.float32)
        if space == "ee_delta":
            low, high = spaces.bounds("ee_delta", {}, None, None)
        else:
            from cake_drake.geometric.ik import Kinematics

            kin = Kinematics()
            low, high = spaces.bounds("joint_position", {}, kin.lower, kin.upper)
        assert len(low) == SKILL_SPACES[space]
        self.action_space = gs.Box(low.astype(np.float32), high.astype(np.float32),
                                   dtype=np.float32)  # fmt: skip
        # The same check a run gets, before make() returns: field names as a scenario's.
        check(self._scenario(0, self.blocks[0]), write=False)
        self._simulator = None
        self._problem, self._first = None, None
        self._built: dict[tuple[int, int], tuple] = {}  # a pool's problems' Diagrams
        self.skill_digest = start_pool.digest(self.skill_path)
        self.starts = str(resolve_path(starts)) if starts else ""
        self._pool = (
            start_pool.read(self.starts, start_pool.settings_of(self), self.skill_digest,
                            self.skill_path) if starts else []
        )  # fmt: skip
        memory = set(getattr(self._lead, "MEMORY", ()))
        for k, start in enumerate(self._pool):
            if start.lead is not None and set(start.lead) != memory:
                raise InputError(f"{self.starts}: starts[{k}].lead is not the memory of "
                                 f"{self.skill_path}'s skill")  # fmt: skip

    def _capture(self) -> start_pool.Start:
        seed, blocks = self._problem
        return start_pool.capture(self._simulator.get_context(), seed, blocks, self._lead)

    @property
    def lead(self):
        """The lead skill (the checkpoint ``skill``, loaded): it does the plan's actions up
        to the episode's, and has answered the episode's first control period; asked on,
        it answers the rest of the action as it would in a run."""
        return self._lead

    # --- the episode --------------------------------------------------------------------

    def _scenario(self, seed: int, blocks: int) -> Scenario:
        s = Scenario() if self.controller is None else Scenario(controller=self.controller)
        s.task.generate = Generate(blocks=blocks, seed=seed, tall=self.tall)
        s.task.planner = self.planner
        s.motion = replace(
            s.motion, skills=self.skill_path, skill_rate_hz=self.rate_hz,
            skill_max_steps=self.budget,
            skill_action_space="relative" if self.relative else "",
        )  # fmt: skip
        set_world(s, self.time_step, self.placement, self.cube_mass_range_kg)
        s.outputs.render = False
        s.seed = seed
        return s

    def _vector(self, o: dict) -> np.ndarray:
        if self.relative:
            return np.asarray(o["observation.relative"], np.float32)
        return np.concatenate([o["observation.state"], o["observation.skill"]]).astype(np.float32)

    def _build(self, scenario: Scenario, checked):
        """The checked problem planned, and its Diagram built under a new simulator;
        the plan."""
        plan, slots, initial = plan_and_layout(checked)
        self._held = HeldSkill(self._lead)
        self._cake = build_diagram(scenario, checked.problem, initial, plan.actions,
                                   slots=slots, skill=self._held)  # fmt: skip
        self._system = self._cake.diagram.GetSubsystemByName("skills")
        self._simulator = Simulator(self._cake.diagram)
        scene = self._cake.scene
        root = self._simulator.get_mutable_context()
        set_world_parameters(scene, scene.plant.GetMyMutableContextFromRoot(root),
                             scenario.world, scenario.seed)  # fmt: skip
        return plan

    def _draw(self, seed: int):
        """The problem of ``seed`` built, and the plan's first actions of the kinds: (the
        cube count, their indices), or why there is none (:data:`NO_START`'s key)."""
        rng = np.random.default_rng(seed)
        blocks = int(rng.integers(self.blocks[0], self.blocks[1] + 1))
        scenario = self._scenario(seed, blocks)
        checked = check(scenario, write=False)
        view = blocksworld_view(checked.problem)
        if view.goal <= view.init:
            return "goal", rng, blocks, []
        plan = self._build(scenario, checked)
        roles = blocksworld_roles(checked.problem.domain)
        kinds = [roles.classify(a).canonical().name for a in plan.actions]
        eligible = [k for k, name in enumerate(kinds[: self.horizon]) if name in self.kinds]
        return (None if eligible else "kinds"), rng, blocks, eligible

    def _begins(self, limit: int):
        """The lead's run from the problem's start: the skill's progress each time an
        action of the kinds begins; over when the run stops or passes ``limit`` periods."""
        self._simulator.Initialize()
        self._t = 0
        while self._t < limit:
            self._t += 1
            self._simulator.AdvanceTo(self._t / self.rate_hz)
            prog = self._progress()
            if prog.error is not None:
                return
            if prog.working >= 0 and prog.steps == 1 and prog.context.schema in self.kinds:
                yield prog

    def _try(self, seed: int) -> str | None:
        """Lead the drawn problem up to its chosen action; None once there, else why not
        (one of :data:`NO_START`'s keys)."""
        why, rng, blocks, eligible = self._draw(seed)
        if why is not None:
            return why
        first = int(rng.choice(eligible))
        # A lead that struggles (repeats, replans) is not waited for: this draw is given
        # up once it has taken LEAD_PERIODS a planned action up to the chosen one.
        for prog in self._begins((first + 1) * LEAD_PERIODS + 1):
            if prog.working >= first:
                self._problem = (seed, blocks)
                self._begin(prog)
                return None
        return "lead"

    def record(self, count: int, seed: int = 0) -> list[start_pool.Start]:
        """``count`` starts for a pool: in the lead's runs of the problems of ``seed``,
        ``seed + 1``, ..., every start a reset could draw (each action of the kinds among
        the plan's first ``horizon``), several a problem, so a pool's problems are few.
        The environment is left at the last start, as a reset leaves it."""
        pool: list[start_pool.Start] = []
        for k in range(count * MAX_DRAWS):
            why, _, blocks, eligible = self._draw(seed + k)
            if why is not None:
                continue
            for prog in self._begins((eligible[-1] + 1) * LEAD_PERIODS + 1):
                if prog.working < self.horizon:
                    self._problem = (seed + k, blocks)
                    pool.append(self._capture())
                if len(pool) == count:  # standing at the last start, as after a reset
                    self._begin(prog)
                    self._first = pool[-1]
                    return pool
                if prog.working >= eligible[-1]:
                    break
        raise ExecutionError(f"CakeDrake/Skill-v0: {len(pool)} starts in {count * MAX_DRAWS} "
                             f"problems, not {count}: the lead skill {self.skill_path} gave "
                             "most runs up")  # fmt: skip

    def _begin(self, prog) -> None:
        """The episode's bookkeeping, at its action's first period ``prog``."""
        self._done, self._succeeded = prog.done, prog.succeeded
        self._ctx, self._schema = prog.context, prog.context.schema
        self._steps = 0
        self._start_z = self._cubes()[self._ctx.cube].translation()[2]

    def _restore(self, start: start_pool.Start) -> None:
        """Stand at ``start``: its problem's Diagram, its state put back; nothing replayed."""
        key = (start.seed, start.blocks)
        if self._problem != key:
            if key in self._built:  # most recently used last
                self._built[key] = self._built.pop(key)
            else:
                scenario = self._scenario(*key)
                self._build(scenario, check(scenario, write=False))
                self._built[key] = (self._held, self._cake, self._system, self._simulator)
                while len(self._built) > BUILT:
                    self._built.pop(next(iter(self._built)))
            self._held, self._cake, self._system, self._simulator = self._built[key]
            self._problem = key
        start_pool.restore(self._simulator.get_mutable_context(), start, self._lead)
        self._simulator.Initialize(InitializeParams(suppress_initialization_events=True))
        self._t = round(start.time * self.rate_hz)
        self._begin(self._progress())

    def start(self) -> start_pool.Start:
        """Where the episode began (after :meth:`reset`): its problem and the Diagram's
        state at its action's first period, as a start pool holds it."""
        if self._first is None:
            raise RuntimeError("call reset() before start()")
        return self._first

    def _progress(self):
        context = self._system.GetMyContextFromRoot(self._simulator.get_context())
        return self._system.progress(context)

    def _cubes(self):
        scene = self._cake.scene
        ctx = scene.plant.GetMyContextFromRoot(self._simulator.get_context())
        return {n: scene.plant.EvalBodyPoseInWorld(ctx, scene.cube_body(n)) for n in scene.cubes}

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if self._pool:
            self._first = self._pool[int(self.np_random.integers(len(self._pool)))]
            self._restore(self._first)
            return self._observe(ended=False)
        why: dict[str, int] = {}
        for _ in range(MAX_DRAWS):
            reason = self._try(int(self.np_random.integers(0, 2**31 - 1)))
            if reason is None:
                self._first = self._capture()
                return self._observe(ended=False)
            why[reason] = why.get(reason, 0) + 1
        kinds = "/".join(self.kinds)
        said = "; ".join(
            f"{n} {NO_START[r].format(skill=self.skill_path, kinds=kinds, horizon=self.horizon)}"
            for r, n in sorted(why.items(), key=lambda item: -item[1])
        )
        raise ExecutionError(f"CakeDrake/Skill-v0: no start in {MAX_DRAWS} draws: {said}")

    def step(self, action):
        if self._simulator is None:
            raise RuntimeError("call reset() before step()")
        given = np.asarray(action, np.float64)
        if given.shape != self.action_space.shape or not np.all(np.isfinite(given)):
            raise InputError(
                f"CakeDrake/Skill-v0 step(): action {np.array2string(given, threshold=8)[:80]}; "
                f"the action space is {self.action_space.shape[0]} finite numbers"
            )
        self._held.action = given
        self._t += 1
        self._simulator.AdvanceTo(self._t / self.rate_hz)
        self._steps += 1
        prog = self._progress()
        ended = prog.done > self._done or prog.error is not None
        obs, info = self._observe(ended, prog)
        terminated = info["unrecoverable"] or (ended and not info["timed_out"])
        truncated = not terminated and (info["timed_out"] or self._steps >= self.budget)
        return obs, info["reward"], terminated, truncated, info

    # --- what the learner sees ----------------------------------------------------------

    def _observe(self, ended: bool, prog=None):
        prog = prog or self._progress()
        o = self._system.observe(self._system.GetMyContextFromRoot(self._simulator.get_context()))
        if o is None:  # the action is over: what the skill read last stands
            o = self._last_obs
        self._last_obs = o
        skill = np.asarray(o["observation.skill"], np.float64)
        cubes = self._cubes()
        ctx, place = self._ctx, self._schema in PLACES
        held = ended and prog.succeeded > self._succeeded
        at = cubes[ctx.cube].translation()
        offset = 0.0
        if place:
            below = ctx.target if ctx.other is None else cubes[ctx.other].translation()
            offset = float(np.hypot(*(at[:2] - np.asarray(below)[:2])))
        lost = any(p.translation()[2] < LOST_Z for p in cubes.values())
        success = held and (not place or offset <= STACK_TOL)
        # the hand's distance to the cube (a pick) or to the place (observation.skill)
        to = skill[8:11] if place else skill[4:7]
        values = {
            "goal": float(held),
            "success": float(success),
            "reach": float(1.0 - np.tanh(np.linalg.norm(to) / rewards.REACH_RANGE)),
            "lift": 0.0 if place else float(np.clip((at[2] - self._start_z) / CUBE_SIZE, 0, 1)),
            "place": max(0.0, 1.0 - offset / rewards.PLACE_RANGE) if place else 0.0,
            "step": 1.0,
            "lost": float(lost),
        }
        info = {
            "reward": rewards.weighted(self.reward, values),
            "reward_terms": values,
            "is_success": bool(success),
            "unrecoverable": bool(lost),
            "timed_out": bool(ended and not held),
            "action": self._schema,
            "offset_mm": 1000.0 * offset if place else None,
            "steps": self._steps,
        }
        return self._vector(o), info
