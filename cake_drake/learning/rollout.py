"""Episodes through ``CakeDrake/Stack-v0``: a policy's rollout, recorded or replayed.

One function runs one episode of the Gymnasium environment (:mod:`cake_drake.gym`) from
a seed, with a policy plug-in acting (:func:`rollout`) or with recorded actions fed open
loop (:func:`replay`). Recording (``python -m cake_drake.record``) and evaluation
(``python -m cake_drake.evaluate``) are loops over these, on a process pool.

The episode's frames are what the policy saw and did: at each step the observation
(``observation.state``: the seven joints and the gripper's width;
``observation.environment_state``: the cubes' poses and the goal as numbers; one image per
camera) and the action it answered, in the environment's control mode, then held for one
control period. Replaying the actions from the same seed therefore rebuilds the same
episode, up to the simulation's own determinism (bit for bit on one machine).

Two teachers' variants of an episode (DART and DAgger) execute an action other than the
one recorded; the recorded one is then the label, and ``executed`` what ran:

- ``EpisodeSpec.noise`` (DART): the policy's action plus seeded Gaussian noise is executed
  (:func:`noise_scale` gives its units per action space, :data:`NOISE_MAX` its bound).
- a :class:`Teacher` (DAgger): the policy is a learner; the teacher answers every step on
  the same observation, and its answer is the label; the teacher's action is executed
  instead with probability ``beta``. Each frame records who acted (``actors``).

The noise and the coin are drawn from the episode's seed: the same seed, the same noise.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from cake_drake.errors import InputError
from cake_drake.geometric.ik import Kinematics
from cake_drake.plugins import DURING, guarded
from cake_drake.policy import spaces
from cake_drake.policy.observations import NO_GROUND_ACTION, SKILL_SIZE
from cake_drake.policy.spaces import EE_STEP
from cake_drake.scenario import ACT_BUDGET_S
from cake_drake.systems.policy_source import make_policy

#: The policy the recordings use unless another is named: the classical cake as a policy
#: (:mod:`cake_drake.learning.policies.expert`, by the path recordings and scenarios name).
EXPERT = "cake_drake.learning.expert:make"
#: Who acted at a frame (the dataset's ``actor``): the labelling policy, or a learner.
EXPERT_ACTED, LEARNER_ACTED = 0, 1
#: The largest noise (``--noise``) each action space takes, in the units of
#: :func:`noise_scale`: 0.1 rad a joint; 0.05 m, the ``ee_delta`` step's own bound.
NOISE_MAX = {"joint_position": 0.1, "ee_delta": 0.05}
#: Streams of the episode's seed: the executed action's noise, DAgger's coin.
NOISE_STREAM, COIN_STREAM = 0xDA27, 0xDA66


def noise_scale(control_mode: str) -> np.ndarray:
    """The standard deviation, per action component, of noise of size 1: ``joint_position``
    1 rad on each of the seven joints; ``ee_delta`` 1 m on dx, dy, dz and the rotations
    scaled as their bounds are (0.25 rad per 0.05 m: 5 rad). The gripper is never noised."""
    if control_mode == "joint_position":
        return np.r_[np.ones(7), 0.0]
    if control_mode == "ee_delta":
        return np.r_[np.ones(3), EE_STEP[3:] / EE_STEP[:3], 0.0]
    raise InputError(
        f"--noise: {control_mode} actions cannot be noised; choose one of: {', '.join(NOISE_MAX)}"
    )


def check_noise(sigma: float, control_mode: str) -> float:
    """``sigma`` if it is noise ``control_mode`` takes; one line (exit 2) naming the bound
    otherwise."""
    unit = "rad on each joint" if control_mode == "joint_position" else "m"
    noise_scale(control_mode)  # a space that cannot be noised
    high = NOISE_MAX[control_mode]
    if not (isinstance(sigma, int | float) and 0.0 <= sigma <= high):
        raise InputError(
            f"--noise {sigma!r}: from 0 to {high:g} ({unit}) for {control_mode} actions"
        )
    return float(sigma)


def _stream(seed: int, stream: int) -> np.random.Generator:
    return np.random.default_rng([seed % 2**32, stream])


@dataclass(frozen=True)
class EpisodeSpec:
    """What the environment of an episode is (the fields of ``StackEnv``)."""

    blocks: int | tuple[int, int] = (3, 8)
    problem: str | None = None
    control_mode: str = "joint_position"
    rate_hz: float = 10.0
    max_steps: int = 0  # 0: scaled to the task's plan (policy.spaces.step_budget)
    cameras: tuple = ()  # cake_drake.world.cameras.Camera, none: state only
    policy: str = EXPERT
    options: dict = field(default_factory=dict)  # the policy's factory's keyword arguments
    placement: tuple[float, float] = (0.0, 0.0)  # world.placement: xy (m), yaw (degrees)
    tall: bool = False  # generated problems of few, tall towers (task.generate.tall)
    cube_mass_range_kg: tuple = ()  # world.cube_mass_range_kg: (lo, hi) kg, drawn per episode
    controller: object = None  # the task's controller (a scenario's), None: the default
    noise: float = 0.0  # DART: noise added to the executed action (units: noise_scale)
    act_budget_s: float = ACT_BUDGET_S  # wall-clock budget of one answer of the policy

    def env(self, render_mode: str | None = None):
        from cake_drake.learning.envs.env import StackEnv  # Gymnasium: an optional extra

        return StackEnv(
            render_mode=render_mode,
            blocks=self.blocks,
            problem=self.problem,
            obs_mode="state+rgb" if self.cameras else "state",
            control_mode=self.control_mode,
            cameras=list(self.cameras) or None,
            rate_hz=self.rate_hz,
            max_steps=self.max_steps,
            options=self.action_options(),
            placement=self.placement,
            tall=self.tall,
            cube_mass_range_kg=self.cube_mass_range_kg,
            controller=self.controller,
        )

    @property
    def label(self) -> str:
        """The policy as its messages and tables name it: its factory, or its checkpoint."""
        return str(self.options.get("path") or self.policy)

    def action_options(self) -> dict:
        """The action space's own options (a chunk's ``horizon`` and ``execute``)."""
        return {k: v for k, v in self.options.items() if k in ("horizon", "execute")}


@dataclass(frozen=True)
class Teacher:
    """DAgger's labeller: the policy whose answer is recorded at every step while the
    episode's own policy (a learner) acts, its action executed instead with probability
    ``beta``."""

    policy: str
    options: dict = field(default_factory=dict)
    beta: float = 0.0


#: An episode's frame arrays (the rest of an :class:`Episode` is its row in a table).
FRAMES = (
    "states", "environment", "actions", "images", "actors", "executed", "skills", "grounds",
    "final",
)  # fmt: skip


@dataclass
class Episode:
    """One episode: its seed, verdict and (when recorded) its frames."""

    seed: int
    success: bool
    reason: str  # why it ended: "goal reached", "policy done", "a cube left the table", ...
    steps: int
    wall_s: float
    task: str = ""  # the instruction in English
    blocks: int = 0
    missing: tuple[str, ...] = ()  # the goal's facts not true at the end, e.g. "(on b a)"
    states: np.ndarray | None = None  # (T, 8) float32
    environment: np.ndarray | None = None  # (T, 240) float32: observation.environment_state
    actions: np.ndarray | None = None  # (T, A) float32
    images: dict[str, np.ndarray] = field(default_factory=dict)  # name -> (T, H, W, 3) uint8
    actors: np.ndarray | None = None  # (T,) int64: EXPERT_ACTED or LEARNER_ACTED
    executed: np.ndarray | None = None  # (T, A) float32: what ran (the label plus noise, ...)
    #: (T, 13) float32 and (T, 4) int64: the labeller's ground action under way at each
    #: frame, as a learned skill reads it (observation.skill) and by name (ground_action).
    skills: np.ndarray | None = None
    grounds: np.ndarray | None = None
    #: (480, 640, 3) uint8: the world at the end of a failed episode (``final_frame``).
    final: np.ndarray | None = None


def _make_policy(spec: str, options: dict):
    return make_policy(spec, options)


def _answer(policy, label: str, obs, spec: EpisodeSpec, kin, counts):
    """``policy``'s answer to ``obs``: (its action checked and clipped, or None; done)."""
    answer = guarded(label, policy.act, obs, exit_code=DURING, budget_s=spec.act_budget_s)
    action, done = spaces.read_answer(answer, label)
    if action is not None:
        options = spec.action_options()
        action = spaces.checked(
            action, spec.control_mode, options, label, kin.lower, kin.upper, counts
        ).astype(np.float32)
    return action, done


def rollout(
    spec: EpisodeSpec,
    seed: int,
    record: bool = True,
    teacher: Teacher | None = None,
    final_frame: bool = False,
) -> Episode:
    """Run the policy ``spec.policy`` for one episode of ``spec.env()`` reset with ``seed``;
    with a ``teacher``, label every step with its answer (see the module); with
    ``final_frame``, a failed episode keeps a picture of how it ended."""
    env = spec.env("rgb_array" if final_frame else None)
    t0 = time.perf_counter()
    obs, info = env.reset(seed=seed)
    task = env.unwrapped.policy_task
    policy = _make_policy(spec.policy, spec.options)
    label = f"policy {spec.label!r}"
    guarded(label, policy.reset, task, seed, exit_code=DURING)
    if teacher is not None:
        expert = _make_policy(teacher.policy, teacher.options)
        expert_label = f"policy {teacher.policy!r}"
        guarded(expert_label, expert.reset, task, seed, exit_code=DURING)
    kin = Kinematics()
    options, counts = spec.action_options(), spaces.Counts()
    noise = spec.noise * noise_scale(spec.control_mode) if spec.noise else None
    noise_rng, coin_rng = _stream(seed, NOISE_STREAM), _stream(seed, COIN_STREAM)
    states, environment, actions, actors, executed = [], [], [], [], []
    skills, grounds = [], []
    images = {c.name: [] for c in spec.cameras}
    reason, steps, ender = "the policy said done", 0, policy
    terminated = truncated = False
    while True:
        action, done = _answer(policy, label, obs, spec, kin, counts)
        if done and action is None:
            break
        labelled, actor, labeller = action, EXPERT_ACTED, policy
        if teacher is not None:
            labeller = expert
            labelled, expert_done = _answer(expert, expert_label, obs, spec, kin, counts)
            if expert_done and labelled is None:
                ender = expert
                break
            done = done or expert_done
            if coin_rng.random() >= teacher.beta:
                actor = LEARNER_ACTED
            else:
                action = labelled
        if noise is not None:
            action = action + noise * noise_rng.standard_normal(action.shape)
            low, high = spaces.bounds(spec.control_mode, options, kin.lower, kin.upper)
            action = np.clip(action, low, high).astype(np.float32)
        if record:
            states.append(np.asarray(obs["state"][:8], np.float32))
            environment.append(obs["environment_state"])
            actions.append(labelled)
            actors.append(actor)
            executed.append(action)
            skill, ground = _skill_observation(labeller)
            skills.append(skill)
            grounds.append(ground)
            for name in images:
                images[name].append(obs["images"][name])
        obs, _, terminated, truncated, info = env.step(action)
        steps += 1
        if terminated or truncated or done:
            break
    if info["is_success"]:
        reason = "goal reached"
    elif terminated:
        reason = "a cube left the table"
    elif truncated:
        periods = spaces.periods(spec.control_mode, options)
        reason = spaces.budget_text(env.unwrapped.budget, spec.rate_hz, periods)
    elif getattr(ender, "reason", None):  # a policy that says why it stopped
        reason = f"the policy said done: {ender.reason}"
    ep = Episode(
        seed, bool(info["is_success"]), reason, steps, time.perf_counter() - t0,
        info["task"], len(info["cubes"]), tuple(info["missing"]),
    )  # fmt: skip
    if final_frame and not ep.success:
        ep.final = env.render()
    if record and actions:
        ep.states, ep.actions = np.stack(states), np.stack(actions)
        ep.environment = np.stack(environment)
        ep.images = {k: np.stack(v) for k, v in images.items()}
        ep.actors, ep.executed = np.asarray(actors, np.int64), np.stack(executed)
        ep.skills, ep.grounds = np.stack(skills), np.stack(grounds)
    return ep


def _skill_observation(policy) -> tuple[np.ndarray, np.ndarray]:
    """The ground action ``policy`` was executing at its last answer, as a skill reads it
    (the closed-loop expert says; any other policy: none)."""
    said = getattr(policy, "skill_observation", None)
    if said is None:
        return np.zeros(SKILL_SIZE, np.float32), NO_GROUND_ACTION.copy()
    skill, ground = said()
    return np.asarray(skill, np.float32), np.asarray(ground, np.int64)


def replay(spec: EpisodeSpec, seed: int, actions: np.ndarray) -> bool:
    """Feed ``actions`` open loop to ``spec.env()`` reset with ``seed``; whether the goal
    is reached (measured from the poses) when they run out."""
    env = spec.env()
    env.reset(seed=seed)
    info = {"is_success": False}
    for action in actions:
        _, _, terminated, truncated, info = env.step(np.asarray(action))
        if terminated or truncated:
            break
    return bool(info["is_success"])
