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
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from cake_drake.plugins import DURING, guarded

#: The policy the recordings use unless another is named: the classical cake as a policy.
EXPERT = "examples.expert_policy:make"
#: Wall-clock budget of one answer of a policy plug-in (s).
ACT_BUDGET_S = 30.0


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

    def env(self):
        from cake_drake.learning.env import StackEnv

        return StackEnv(
            blocks=self.blocks,
            problem=self.problem,
            obs_mode="state+rgb" if self.cameras else "state",
            control_mode=self.control_mode,
            cameras=list(self.cameras) or None,
            rate_hz=self.rate_hz,
            max_steps=self.max_steps,
            options=self.action_options(),
            placement=self.placement,
        )

    @property
    def label(self) -> str:
        """The policy as its messages and tables name it: its factory, or its checkpoint."""
        return str(self.options.get("path") or self.policy)

    def action_options(self) -> dict:
        """The action space's own options (a chunk's ``horizon`` and ``execute``)."""
        return {k: v for k, v in self.options.items() if k in ("horizon", "execute")}


#: An episode's frame arrays (the rest of an :class:`Episode` is its row in a table).
FRAMES = ("states", "environment", "actions", "images")


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
    states: np.ndarray | None = None  # (T, 8) float32
    environment: np.ndarray | None = None  # (T, 240) float32: observation.environment_state
    actions: np.ndarray | None = None  # (T, A) float32
    images: dict[str, np.ndarray] = field(default_factory=dict)  # name -> (T, H, W, 3) uint8


def _make_policy(spec: str, options: dict):
    from cake_drake.systems.policy_source import make_policy

    return make_policy(spec, options)



def rollout(spec: EpisodeSpec, seed: int, record: bool = True) -> Episode:
    """Run the policy ``spec.policy`` for one episode of ``spec.env()`` reset with ``seed``."""
    from cake_drake.geometric.ik import Kinematics
    from cake_drake.policy import spaces

    env = spec.env()
    t0 = time.perf_counter()
    obs, info = env.reset(seed=seed)
    policy = _make_policy(spec.policy, spec.options)
    label = f"policy {spec.label!r}"
    guarded(label, policy.reset, env.unwrapped.policy_task, seed, exit_code=DURING)
    kin = Kinematics()
    options, counts = spec.action_options(), spaces.Counts()
    states, environment, actions = [], [], []
    images = {c.name: [] for c in spec.cameras}
    reason, steps = "the policy said done", 0
    terminated = truncated = False
    while True:
        answer = guarded(label, policy.act, obs, exit_code=DURING, budget_s=ACT_BUDGET_S)
        action, done = spaces.read_answer(answer, label)
        if done and action is None:
            break
        action = spaces.checked(
            action, spec.control_mode, options, label, kin.lower, kin.upper, counts
        ).astype(np.float32)
        if record:
            states.append(np.asarray(obs["state"][:8], np.float32))
            environment.append(obs["environment_state"])
            actions.append(action)
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
    elif getattr(policy, "reason", None):  # a policy that says why it stopped
        reason = f"the policy said done: {policy.reason}"
    ep = Episode(
        seed, bool(info["is_success"]), reason, steps, time.perf_counter() - t0,
        info["task"], len(info["cubes"]),
    )  # fmt: skip
    if record and actions:
        ep.states, ep.actions = np.stack(states), np.stack(actions)
        ep.environment = np.stack(environment)
        ep.images = {k: np.stack(v) for k, v in images.items()}
    return ep


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
