"""The ``cake_mlp`` policy's configuration (see :mod:`cake_drake.learning.policies.mlp`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from lerobot.configs.policies import PreTrainedConfig
from lerobot.configs.types import NormalizationMode
from lerobot.optim.optimizers import AdamWConfig
from lerobot.optim.schedulers import CosineDecayWithWarmupSchedulerConfig


@PreTrainedConfig.register_subclass("cake_mlp")
@dataclass
class CakeMLPConfig(PreTrainedConfig):
    """A multilayer perceptron from the state (``observation.state`` and
    ``observation.environment_state``: a whole-task policy; or ``observation.state`` and
    ``observation.skill``: a learned skill, conditioned on the ground action it executes)
    to a chunk of ``chunk_size`` actions, of which ``n_action_steps`` are executed before
    it is asked again.

    A policy that sees reads ``observation.state`` and cameras (``observation.images.*``)
    instead of the cubes' poses, and ``observation.goal`` (the goal as numbers, no pose):
    each camera's latest frame goes through an encoder of its own (four 3x3 convolutions
    of ``vision_channels`` and a spatial softmax of ``vision_keypoints`` keypoints), moved
    by up to ``crop_shift`` pixels at random in training.

    With ``relative_joints`` the arm's seven joint targets are learned as offsets from the
    measured joints (the gripper's width as itself): the network says where to move from
    here, which generalises over where the cubes stand better than absolute targets. The
    policy standardises its own inputs and outputs with the dataset's statistics, each
    spread floored at ``min_std`` (a number that never varied in the demonstrations, such
    as a zero-padded cube or a cube's tilt, must not be blown up when it varies once); the
    statistics are buffers of the model, saved with its weights.
    """

    #: Observations read at once: the current one and the ones before it (two tell the
    #: arm's velocity, which a joint target leads by).
    n_obs_steps: int = 1
    chunk_size: int = 10
    n_action_steps: int = 5
    hidden_dims: list[int] = field(default_factory=lambda: [512, 512, 512])
    dropout: float = 0.0
    relative_joints: bool = True
    min_std: float = 0.01
    #: Gaussian noise (in standard deviations) added to the standardised inputs in training.
    input_noise: float = 0.0
    #: A camera's encoder: channels of its convolutions, keypoints out (two numbers each).
    vision_channels: int = 32
    vision_keypoints: int = 32
    #: Random shift of each training image, in pixels (0: none).
    crop_shift: int = 4
    normalization_mapping: dict[str, NormalizationMode] = field(
        default_factory=lambda: {
            "VISUAL": NormalizationMode.IDENTITY,
            "STATE": NormalizationMode.IDENTITY,
            "ENV": NormalizationMode.IDENTITY,
            "ACTION": NormalizationMode.IDENTITY,
        }
    )
    optimizer_lr: float = 1e-3
    optimizer_weight_decay: float = 1e-4
    #: The cosine schedule's length in steps (``train`` sets it to the recipe's steps).
    scheduler_decay_steps: int = 10_000
    scheduler_warmup_steps: int = 100

    def __post_init__(self) -> None:
        super().__post_init__()
        if not 1 <= self.n_action_steps <= self.chunk_size:
            raise ValueError(
                f"n_action_steps {self.n_action_steps}: 1 to chunk_size ({self.chunk_size})"
            )
        if not 1 <= self.n_obs_steps <= 10:
            raise ValueError(f"n_obs_steps {self.n_obs_steps}: 1 to 10 observations")

    def get_optimizer_preset(self) -> AdamWConfig:
        return AdamWConfig(lr=self.optimizer_lr, weight_decay=self.optimizer_weight_decay)

    def get_scheduler_preset(self) -> CosineDecayWithWarmupSchedulerConfig:
        return CosineDecayWithWarmupSchedulerConfig(
            num_warmup_steps=self.scheduler_warmup_steps,
            num_decay_steps=self.scheduler_decay_steps,
            peak_lr=self.optimizer_lr,
            decay_lr=self.optimizer_lr * 0.01,
        )

    def validate_features(self) -> None:
        extra = ("observation.environment_state", "observation.skill")
        if not self.robot_state_feature or not (
            self.image_features or any(k in self.input_features for k in extra)
        ):
            raise ValueError(
                "cake_mlp needs observation.state and observation.environment_state (a "
                "whole-task policy), observation.skill (a learned skill) or cameras (a "
                "policy that sees)"
            )
        if self.image_features and "observation.environment_state" in self.input_features:
            raise ValueError(
                "cake_mlp sees the cubes or reads their poses, not both: drop "
                "observation.environment_state or the cameras"
            )

    @property
    def observation_delta_indices(self) -> list[int] | None:
        return list(range(1 - self.n_obs_steps, 1)) if self.n_obs_steps > 1 else None

    @property
    def action_delta_indices(self) -> list[int]:
        return list(range(self.chunk_size))

    @property
    def reward_delta_indices(self) -> None:
        return None
