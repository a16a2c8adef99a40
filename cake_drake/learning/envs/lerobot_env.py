"""The learning tasks as a LeRobot environment: ``lerobot-eval --env.type=cake_drake``.

LeRobot 0.6 finds environments of other packages by their distribution's name: it
imports every installed ``lerobot_env_*`` at start-up. The one-file distribution
``plugins/lerobot_env_cake_drake`` (``make test`` installs it; elsewhere ``pip install -e
plugins/lerobot_env_cake_drake``) imports this module, which registers the environment
type ``cake_drake``: ``--env.task`` names a task of ``models/scenarios/learning.yaml``
(``stack2``, ``tower3``, ``tower5``, ``blocks3``), whose episodes are those
``python -m cake_drake.evaluate`` runs (:class:`cake_drake.learning.envs.env.StackEnv` with
the task's placement, action space, rate and budget). Its observations are named as
LeRobot's own environments name theirs: ``agent_pos`` (the joints and the gripper,
LeRobot's ``observation.state``), ``environment_state`` (the cubes and the goal) and
``pixels`` (the task's cameras); ``info["is_success"]`` is the goal reached. The
command docs/learning.md shows: ``lerobot-eval --policy.path=models/policies/stack2
--env.type=cake_drake --env.task=stack2 ...``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import gymnasium
import numpy as np
from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.utils.constants import ACTION, OBS_ENV_STATE, OBS_IMAGES, OBS_STATE

from cake_drake.learning.data.recording import learning_tasks, spec_from_scenario
from cake_drake.policy.observations import ENVIRONMENT_STATE_SIZE
from cake_drake.scenario import load_scenario

LEARNING = Path(__file__).resolve().parents[3] / "models" / "scenarios" / "learning.yaml"
#: The joints and the gripper's width: what a recording's ``observation.state`` holds.
STATE = 8


class LeRobotObservations(gymnasium.Wrapper):
    """A :class:`StackEnv` with LeRobot's observation names, its task in English, and a
    step budget LeRobot can read (``_max_episode_steps``)."""

    def __init__(self, env, max_steps: int) -> None:
        super().__init__(env)
        self._max_episode_steps = max_steps
        self.task_description = self.task = ""
        parts = {
            "agent_pos": gymnasium.spaces.Box(-np.inf, np.inf, (STATE,), np.float32),
            "environment_state": env.observation_space["environment_state"],
        }
        if "images" in env.observation_space.spaces:
            parts["pixels"] = env.observation_space["images"]
        self.observation_space = gymnasium.spaces.Dict(parts)

    def _rename(self, obs: dict, info: dict) -> dict:
        self.task_description = self.task = str(info.get("task", ""))
        out = {
            "agent_pos": np.asarray(obs["state"][:STATE], np.float32),
            "environment_state": np.asarray(obs["environment_state"], np.float32),
        }
        if "images" in obs:
            out["pixels"] = dict(obs["images"])
        return out

    def reset(self, **kwargs):
        kwargs.pop("options", None)  # LeRobot's rollout marker: not an option of ours
        obs, info = self.env.reset(**kwargs)
        return self._rename(obs, info), info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        return self._rename(obs, info), reward, terminated, truncated, info


@EnvConfig.register_subclass("cake_drake")
@dataclass
class CakeDrakeEnv(EnvConfig):
    """A learning task of ``models/scenarios/learning.yaml`` (``task``) for lerobot-eval."""

    task: str | None = "stack2"
    fps: int = 10
    #: The most steps an episode may take (LeRobot's progress bar and budget): the task's
    #: own budget ends it sooner where it is smaller.
    episode_length: int = 1000
    features: dict[str, PolicyFeature] = field(default_factory=dict)
    features_map: dict[str, str] = field(
        default_factory=lambda: {
            ACTION: ACTION,
            "agent_pos": OBS_STATE,
            "environment_state": OBS_ENV_STATE,
        }
    )

    def __post_init__(self) -> None:
        spec = self._spec()
        action = 8 if spec.control_mode == "joint_position" else 7
        self.features = {
            ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(action,)),
            "agent_pos": PolicyFeature(type=FeatureType.STATE, shape=(STATE,)),
            "environment_state": PolicyFeature(
                type=FeatureType.ENV, shape=(ENVIRONMENT_STATE_SIZE,)
            ),
        }
        for c in spec.cameras:
            self.features[f"pixels/{c.name}"] = PolicyFeature(
                type=FeatureType.VISUAL, shape=(c.height, c.width, 3)
            )
            self.features_map[f"pixels/{c.name}"] = f"{OBS_IMAGES}.{c.name}"
        self.fps = int(round(spec.rate_hz))

    def _spec(self):
        names = learning_tasks(LEARNING)
        if self.task not in names:
            raise ValueError(f"--env.task {self.task!r}; choose one of: {', '.join(names)}")
        return spec_from_scenario(load_scenario(LEARNING, self.task))

    @property
    def gym_kwargs(self) -> dict:
        return {}

    def create_envs(self, n_envs: int, use_async_envs: bool = False) -> dict:
        spec = self._spec()

        def make():
            return LeRobotObservations(spec.env(), self.episode_length)

        vector = gymnasium.vector.AsyncVectorEnv if use_async_envs and n_envs > 1 else (
            gymnasium.vector.SyncVectorEnv
        )  # fmt: skip
        return {self.type: {0: vector([make for _ in range(n_envs)])}}
