"""``CakeDrake/Stack-v0``: the Blocksworld task as a Gymnasium environment.

A thin face over the same Diagram a run builds: each ``reset(seed=...)`` draws a problem
(a generated Blocksworld of ``blocks`` cubes, or the given PDDL problem), lays it out as a
run would, and builds the Diagram with a ``!Policy`` reference whose policy is this
environment: ``step(action)`` holds the action for one control period (``1 / rate_hz``
simulated seconds) and returns what the policy slot observes.

- ``control_mode``: an action space of :mod:`cake_drake.policy.spaces` (``ee_delta``,
  ``joint_position``, ``joint_chunk``); a ``joint_chunk`` step executes ``execute`` rows
  of the chunk (``execute`` control periods).
- ``obs_mode``: ``state`` (``state``: joints, gripper width, joint velocities and the grasp
  frame's pose, 22 numbers; ``cubes``: 12 rows of cube poses, zero past the problem's
  cubes; ``environment_state``: the cubes' poses and the goal as numbers, 240, the layout
  of :mod:`cake_drake.policy.observations`), ``rgb`` (``images``: one RGB image per
  camera) or ``state+rgb``.
- ``placement``: ``(xy, yaw_deg)``, each tower's place jittered by up to ``xy`` m and each
  cube turned by up to ``yaw_deg`` per seed (the scenario's ``world.placement``).
- ``tall``: generated problems of few, tall towers, start and goal (the scenario's
  ``task.generate.tall``).
- ``cube_mass_range_kg``: ``(lo, hi)``, the cubes' mass drawn per episode from its seed
  (the scenario's ``world.cube_mass_range_kg``); empty: the cubes' own 0.05 kg.
- ``controller``: the controller below (a scenario's ``controller``, e.g.
  ``ComputedTorque(kp=[400.0], kd=[40.0])``); None: a run's default.
- every argument is checked when the environment is made, by the same ``check`` a
  scenario gets, with the same field names.
- a generated problem whose goal already holds is drawn again (the same seed always
  gives the same problem).
- reward: the fraction of the goal's facts measured true in the world, or the terms of
  :mod:`cake_drake.learning.envs.rewards` weighed by ``reward`` (a mapping, term -> weight:
  ``{"goal": 1.0, "place": 0.5}``; ``info["reward_terms"]`` has every term); ``info`` has
  ``is_success`` (every goal fact true, every stacked cube within 5 mm of the one below),
  the English instruction ``task``, the ``goal`` facts and those ``missing`` (not
  measured true now).
- ``terminated`` on success, or when a cube has left the table (the world cannot be
  recovered); ``truncated`` after ``max_steps`` steps (0, the default: scaled to the
  task, 20 s plus 8 s per action of the classical plan; ``env.unwrapped.budget``).
- the observation is the policy slot's own, computed once per control period: each
  camera renders once a step.

Drake's own ``pydrake.gym.DrakeGymEnv`` wraps one fixed Diagram; here each reset may bring
a different number of cubes, so a new Diagram is built per reset.

    import gymnasium
    env = gymnasium.make("cake_drake.gym:CakeDrake/Stack-v0", control_mode="ee_delta")
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import fields

import gymnasium
import numpy as np
from gymnasium import spaces as gs
from pydrake.systems.analysis import Simulator

from cake_drake.diagram import build_diagram
from cake_drake.errors import InputError
from cake_drake.geometric.ik import Kinematics
from cake_drake.learning.envs import rewards
from cake_drake.pipeline import check, plan_and_layout
from cake_drake.policy import spaces
from cake_drake.policy.observations import ENVIRONMENT_STATE_SIZE, MAX_CUBES
from cake_drake.scenario import Generate, Policy, Reward, Scenario
from cake_drake.symbolic.roles import blocksworld_view
from cake_drake.world.cameras import Camera, default_cameras
from cake_drake.world.render import Renderer
from cake_drake.world.scene import Placement, cube_poses, set_world_parameters

OBS_MODES = ("state", "rgb", "state+rgb")
STATE_SIZE = 22


class HeldAction:
    """The policy the Diagram asks: it answers with the action the environment was given."""

    action = None
    label = "the action given to CakeDrake/Stack-v0's step()"
    act_budget_s = None  # it only hands over what step() was given

    def reset(self, task, seed) -> None:
        pass

    def act(self, observation):
        return self.action


def _blocks(blocks) -> tuple[int, int]:
    """``blocks`` as (fewest, most): a whole number or a pair of them, 1 to 12."""
    pair = (blocks, blocks) if not isinstance(blocks, Sequence | np.ndarray) else tuple(blocks)
    whole = (
        all(isinstance(b, int | np.integer) and not isinstance(b, bool) for b in pair)
        and len(pair) == 2
    )
    if not whole or not 1 <= pair[0] <= pair[1] <= MAX_CUBES:
        raise InputError(
            f"blocks = {blocks!r:.40}: a number of cubes, or a range (fewest, most), "
            f"whole numbers from 1 to {MAX_CUBES}"
        )
    return int(pair[0]), int(pair[1])


def _cameras(cameras) -> list[Camera]:
    """Cameras as :class:`Camera`; a mapping of a camera's fields is read as one."""
    if cameras is None:
        return default_cameras()
    if not isinstance(cameras, Sequence) or isinstance(cameras, str):
        raise InputError(f"cameras = {cameras!r:.40}: a list of cameras")
    known = {f.name for f in fields(Camera)}
    out = []
    for k, c in enumerate(cameras):
        if isinstance(c, Camera):
            out.append(c)
        elif isinstance(c, Mapping):
            unknown = sorted(set(c) - known)
            if unknown:
                raise InputError(
                    f"cameras[{k}]: unknown field {unknown[0]!r}; valid: {', '.join(sorted(known))}"
                )
            out.append(Camera(**c))
        else:
            raise InputError(
                f"cameras[{k}] = {c!r:.40}: a Camera, or a mapping of its fields "
                f"({', '.join(sorted(known))})"
            )
    return out


def set_world(s: Scenario, time_step: float, placement, cube_mass_range_kg) -> None:
    """An environment's world arguments into the scenario ``s`` (checked later by the same
    ``check`` a scenario gets); one line naming the argument where one is no such value."""
    s.world.time_step = time_step
    try:
        xy, yaw_deg = placement
    except (TypeError, ValueError):
        raise InputError(f"placement = {placement!r:.40}: (xy in m, yaw in degrees)") from None
    s.world.placement = Placement(xy=xy, yaw_deg=yaw_deg)
    try:
        s.world.cube_mass_range_kg = [float(m) for m in cube_mass_range_kg]
    except (TypeError, ValueError):
        raise InputError(
            f"cube_mass_range_kg = {cube_mass_range_kg!r:.40}: [lo, hi] kg or empty"
        ) from None


class StackEnv(gymnasium.Env):
    """See the module's docstring."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        blocks: int | tuple[int, int] = (3, 8),
        problem: str | None = None,
        obs_mode: str = "state",
        control_mode: str = "ee_delta",
        cameras: list[Camera] | None = None,
        rate_hz: float = 10.0,
        max_steps: int = 0,
        time_step: float = 0.01,
        options: dict | None = None,
        render_mode: str | None = None,
        placement: tuple[float, float] = (0.0, 0.0),
        tall: bool = False,
        reward: Mapping | None = None,
        cube_mass_range_kg: Sequence[float] = (),
        controller=None,
    ) -> None:
        if obs_mode not in OBS_MODES:
            raise InputError(f"obs_mode {obs_mode!r}; choose one of: {', '.join(OBS_MODES)}")
        if render_mode not in (None, "rgb_array"):
            raise InputError(f"render_mode {render_mode!r}; choose rgb_array or None")
        if not isinstance(options or {}, Mapping):
            raise InputError(f"options = {options!r:.40}: a mapping of the action space's options")
        self.options = dict(options or {})
        self.blocks, self.problem = _blocks(blocks), problem
        self.obs_mode, self.control_mode = obs_mode, control_mode
        self.cameras = _cameras(cameras) if "rgb" in obs_mode else []
        whole = isinstance(max_steps, int | np.integer) and not isinstance(max_steps, bool)
        if not (whole and 0 <= max_steps <= 1_000_000):
            raise InputError(
                f"max_steps = {max_steps!r:.24}: a whole number of steps from 0 (scaled to "
                "the task) to 1000000"
            )
        self.rate_hz, self.max_steps, self.time_step = rate_hz, int(max_steps), time_step
        self.placement = placement
        if not isinstance(tall, bool):
            raise InputError(f"tall = {tall!r:.40}: true or false")
        self.tall = tall
        self.cube_mass_range_kg = cube_mass_range_kg
        #: The task's controller (cake_drake.dynamic.controllers), None: a run's default.
        self.controller = controller
        #: The reward's weights (cake_drake.learning.envs.rewards): the goal's fraction alone
        #: unless given.
        self.reward = rewards.check_reward(Reward() if reward is None else reward, "reward")
        self.render_mode = render_mode
        # The same check a scenario gets, before make() returns: field names as a scenario's.
        self._checked_template = check(self._scenario(0, self.blocks[0]), write=False)
        self._periods = spaces.periods(control_mode, self.options)
        kin = Kinematics()
        low, high = spaces.bounds(control_mode, self.options, kin.lower, kin.upper)
        self.action_space = gs.Box(
            low.astype(np.float32), high.astype(np.float32), dtype=np.float32
        )
        parts = {}
        if "state" in obs_mode:
            parts["state"] = gs.Box(-np.inf, np.inf, (STATE_SIZE,), np.float32)
            parts["cubes"] = gs.Box(-np.inf, np.inf, (MAX_CUBES, 7), np.float32)
            parts["environment_state"] = gs.Box(
                -np.inf, np.inf, (ENVIRONMENT_STATE_SIZE,), np.float32
            )
        if "rgb" in obs_mode:
            parts["images"] = gs.Dict(
                {c.name: gs.Box(0, 255, (c.height, c.width, 3), np.uint8) for c in self.cameras}
            )
        self.observation_space = gs.Dict(parts)
        self._simulator = None

    # --- the episode --------------------------------------------------------------------

    def _scenario(self, seed: int, blocks: int | None = None):
        s = Scenario() if self.controller is None else Scenario(controller=self.controller)
        if self.problem is None:
            if blocks is None:
                blocks = int(self.np_random.integers(self.blocks[0], self.blocks[1] + 1))
            s.task.generate = Generate(blocks=blocks, seed=seed, tall=self.tall)
        else:
            s.task.problem = self.problem
        s.reference = Policy(
            factory="cake_drake.learning.envs.env:HeldAction",
            action_space=self.control_mode,
            rate_hz=self.rate_hz,
            max_steps=1_000_000,  # the environment keeps the budget (``step``)
            options=self.options,
        )
        set_world(s, self.time_step, self.placement, self.cube_mass_range_kg)
        s.cameras = list(self.cameras)
        s.outputs.render = False
        s.seed = seed
        return s

    def _draw(self):
        """This episode's scenario (problem, placement, seed) and its check, drawn from the
        env's random stream: a generated goal that already holds is no episode."""
        episode_seed = int(self.np_random.integers(0, 2**31 - 1))
        for _ in range(100):
            scenario = self._scenario(episode_seed)
            checked = check(scenario, write=False)
            view = blocksworld_view(checked.problem)
            if self.problem is not None or not view.goal <= view.init:
                break
            episode_seed = int(self.np_random.integers(0, 2**31 - 1))
        return scenario, checked

    def episode_scenario(self, seed: int):
        """The scenario ``reset(seed=seed)`` runs (its problem, placement and seed), as a
        run would take it: for running the same episode another way (a run with learned
        skills under the planner)."""
        gymnasium.Env.reset(self, seed=seed)
        return self._draw()[0]

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        scenario, checked = self._draw()
        view = blocksworld_view(checked.problem)
        plan, slots, initial = plan_and_layout(checked)
        self._held = HeldAction()
        self._cake = build_diagram(
            scenario, checked.problem, initial, plan.actions, slots=slots, policy=self._held
        )
        self._view = view
        self._goal = frozenset(view.goal)
        self._source = self._cake.reference.policy
        #: What a policy is told at its reset (a policy that plans reads the problem here).
        self.policy_task = self._source.task
        self._simulator = Simulator(self._cake.diagram)
        scene = self._cake.scene
        plant_context = scene.plant.GetMyMutableContextFromRoot(
            self._simulator.get_mutable_context()
        )
        set_world_parameters(scene, plant_context, scenario.world, scenario.seed)
        self._simulator.Initialize()
        self._context = self._simulator.get_context()
        self._source_context = self._source.GetMyContextFromRoot(self._context)
        self._steps = 0
        self._period_index = 0
        self._start_z = None  # the cubes' heights as the episode begins (the lift term)
        #: This episode's step budget: ``max_steps``, or (0) scaled to the classical plan.
        self.budget = spaces.step_budget(
            self.max_steps, len(plan.actions), self.rate_hz, self._periods
        )
        return self._observe()

    def step(self, action):
        if self._simulator is None:
            raise RuntimeError("call reset() before step()")
        self._held.action = action
        # To the slot's next update time exactly as Drake computes it (k periods from 0):
        # a sum of periods drifts off it, and the update would then observe a second time.
        self._period_index += self._periods
        self._simulator.AdvanceTo(self._period_index * (1.0 / self.rate_hz))
        self._steps += 1
        obs, info = self._observe()
        terminated = info["is_success"] or info["unrecoverable"]
        truncated = not terminated and self._steps >= self.budget
        return obs, info["reward"], terminated, truncated, info

    def render(self):
        if self.render_mode != "rgb_array" or self._simulator is None:
            return None
        scene = self._cake.scene
        plant_context = scene.plant.GetMyContextFromRoot(self._context)
        q = scene.plant.GetPositions(plant_context, scene.arm)
        fingers = float(scene.plant.GetPositions(plant_context, scene.hand)[0])
        if not hasattr(self, "_renderer"):
            self._renderer = Renderer(list(self._view.blocks), 640, 480)
        return self._renderer.render(cube_poses(scene, plant_context), q, fingers)[:, :, :3]

    # --- what the agent sees ------------------------------------------------------------

    def _observe(self):
        # The slot's own observation of this period: the policy's update at this time
        # reads the same object, so each camera renders once a step.
        o = self._source.observe(self._source_context)
        obs = {}
        if "state" in self.obs_mode:
            obs["state"] = np.concatenate(
                [o["observation.state"], o["observation.velocity"], o["observation.ee_pose"]]
            )
            cubes = np.zeros((MAX_CUBES, 7), np.float32)
            cubes[: len(o["cubes"])] = o["observation.cubes"]
            obs["cubes"] = cubes
            obs["environment_state"] = o["observation.environment_state"]
        if "rgb" in self.obs_mode:
            obs["images"] = {c.name: o[f"observation.images.{c.name}"] for c in self.cameras}
        progress = self._source.progress(o)  # the slot's reading: once per observation
        positions = np.asarray(o["observation.cubes"], np.float64)[:, :3]
        if self._start_z is None:
            self._start_z = positions[:, 2].copy()
        values = rewards.terms(
            progress, self._goal, list(o["cubes"]), positions,
            np.asarray(o["observation.ee_pose"][:3], np.float64), self._start_z,
        )  # fmt: skip
        info = {
            "reward": rewards.weighted(self.reward, values),
            "reward_terms": values,
            "is_success": progress.reached,
            "unrecoverable": progress.lost,
            "task": o["task"],
            "goal": o["goal"],
            "missing": tuple(sorted(f"({' '.join(f)})" for f in progress.missing)),
            "cubes": o["cubes"],
            "steps": self._steps,
        }
        return obs, info
