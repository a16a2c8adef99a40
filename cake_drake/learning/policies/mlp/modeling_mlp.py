"""The ``cake_mlp`` policy: a multilayer perceptron over the state (and, for a policy that
sees, each camera's keypoints) that predicts a chunk of joint-position actions (see
:class:`CakeMLPConfig`). The arithmetic lives in :mod:`cake_drake.learning.policies.mlp.network`
(torch alone); this is LeRobot's face of it: a ``PreTrainedPolicy`` with the training
loss."""

from __future__ import annotations

from lerobot.policies.pretrained import PreTrainedPolicy
from lerobot.utils.constants import ACTION
from torch import Tensor

from cake_drake.learning.policies.mlp.configuration_mlp import CakeMLPConfig
from cake_drake.learning.policies.mlp.features import camera_shapes, input_sizes
from cake_drake.learning.policies.mlp.network import Chunks


class CakeMLPPolicy(Chunks, PreTrainedPolicy):
    """See :class:`CakeMLPConfig`."""

    config_class = CakeMLPConfig
    name = "cake_mlp"

    def __init__(self, config: CakeMLPConfig, dataset_stats: dict | None = None, **kwargs):
        PreTrainedPolicy.__init__(self, config)
        config.validate_features()
        features = config.input_features
        cameras = camera_shapes(features)
        action = config.action_feature.shape[0]
        self.build(config, input_sizes(features), action, dataset_stats, cameras)

    def get_optim_params(self) -> dict:
        return self.parameters()

    def forward(self, batch: dict[str, Tensor], reduction: str = "mean") -> tuple[Tensor, dict]:
        target = (batch[ACTION] - self._origin(batch)) / self.action_std
        error = (self._chunk(batch) - target).abs()
        if "action_is_pad" in batch:
            error = error * ~batch["action_is_pad"].unsqueeze(-1)
        per_sample = error.mean(dim=(1, 2))
        loss = per_sample if reduction == "none" else per_sample.mean()
        return loss, {"l1_loss": float(per_sample.mean().detach())}

    # Chunks' inference, under LeRobot's names (PreTrainedPolicy declares them abstract).
    predict_action_chunk = Chunks.predict_action_chunk
    select_action = Chunks.select_action
    reset = Chunks.reset
