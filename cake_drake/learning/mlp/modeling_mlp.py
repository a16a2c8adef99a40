"""The ``cake_mlp`` policy: a multilayer perceptron over the state that predicts a chunk of
joint-position actions (see :class:`CakeMLPConfig`)."""

from __future__ import annotations

from collections import deque

import torch
from lerobot.policies.pretrained import PreTrainedPolicy
from lerobot.utils.constants import ACTION, OBS_ENV_STATE, OBS_STATE
from torch import Tensor, nn

from cake_drake.learning.mlp.configuration_mlp import CakeMLPConfig

#: The arm's joints in a joint_position action (the gripper's width follows).
ARM = 7


def _stats(stats: dict | None, key: str, size: int, floor: float) -> tuple[Tensor, Tensor]:
    """Mean and floored spread of feature ``key`` (zeros and ones when there are none: a
    policy loaded from a checkpoint gets its statistics from the weights)."""
    if stats and key in stats:
        mean = torch.as_tensor(stats[key]["mean"], dtype=torch.float32).reshape(size)
        std = torch.as_tensor(stats[key]["std"], dtype=torch.float32).reshape(size)
        return mean, std.clamp_min(floor)
    return torch.zeros(size), torch.ones(size)


class CakeMLPPolicy(PreTrainedPolicy):
    """See :class:`CakeMLPConfig`."""

    config_class = CakeMLPConfig
    name = "cake_mlp"

    def __init__(self, config: CakeMLPConfig, dataset_stats: dict | None = None, **kwargs):
        super().__init__(config)
        config.validate_features()
        self.config = config
        state = config.robot_state_feature.shape[0]
        env = config.env_state_feature.shape[0]
        self.action_dim = config.action_feature.shape[0]
        if config.relative_joints and (self.action_dim < ARM or state < ARM):
            raise ValueError("relative_joints needs 7 arm joints in the state and the action")
        floor = config.min_std
        for name, key, size in (
            ("state", OBS_STATE, state),
            ("env", OBS_ENV_STATE, env),
            ("action", ACTION, self.action_dim),
        ):
            mean, std = _stats(dataset_stats, key, size, floor)
            self.register_buffer(f"{name}_mean", mean)
            self.register_buffer(f"{name}_std", std)
        layers: list[nn.Module] = []
        width = (state + env) * config.n_obs_steps
        for hidden in config.hidden_dims:
            layers += [nn.Linear(width, hidden), nn.GELU()]
            if config.dropout:
                layers.append(nn.Dropout(config.dropout))
            width = hidden
        layers.append(nn.Linear(width, config.chunk_size * self.action_dim))
        self.net = nn.Sequential(*layers)
        self.reset()

    def get_optim_params(self) -> dict:
        return self.parameters()

    def reset(self) -> None:
        self._queue: deque[Tensor] = deque([], maxlen=self.config.n_action_steps)
        self._seen: deque[dict[str, Tensor]] = deque([], maxlen=self.config.n_obs_steps)

    def _inputs(self, batch: dict[str, Tensor]) -> Tensor:
        """The standardised observations, oldest first, side by side: (B, n_obs_steps * D)."""
        state = (batch[OBS_STATE] - self.state_mean) / self.state_std
        env = (batch[OBS_ENV_STATE] - self.env_mean) / self.env_std
        x = torch.cat([state, env], dim=-1)
        if x.dim() == 3:  # (B, n_obs_steps, D): lerobot's frames before the current one
            x = x.flatten(1)
        if self.training and self.config.input_noise:
            x = x + self.config.input_noise * torch.randn_like(x)
        return x

    def _origin(self, batch: dict[str, Tensor]) -> Tensor:
        """What the network's standardised output is measured from: the measured joints
        (relative) or the dataset's mean action, (B, 1, action_dim)."""
        now = batch[OBS_STATE] if batch[OBS_STATE].dim() == 2 else batch[OBS_STATE][:, -1]
        origin = self.action_mean.expand(now.shape[0], -1).clone()
        if self.config.relative_joints:
            origin[:, :ARM] = now[:, :ARM]
        return origin.unsqueeze(1)

    def _chunk(self, batch: dict[str, Tensor]) -> Tensor:
        """The standardised chunk, (B, chunk_size, action_dim)."""
        out = self.net(self._inputs(batch))
        return out.view(-1, self.config.chunk_size, self.action_dim)

    def forward(self, batch: dict[str, Tensor], reduction: str = "mean") -> tuple[Tensor, dict]:
        target = (batch[ACTION] - self._origin(batch)) / self.action_std
        error = (self._chunk(batch) - target).abs()
        if "action_is_pad" in batch:
            error = error * ~batch["action_is_pad"].unsqueeze(-1)
        per_sample = error.mean(dim=(1, 2))
        loss = per_sample if reduction == "none" else per_sample.mean()
        return loss, {"l1_loss": float(per_sample.mean().detach())}

    @torch.no_grad()
    def predict_action_chunk(self, batch: dict[str, Tensor], **kwargs) -> Tensor:
        self.eval()
        return self._origin(batch) + self._chunk(batch) * self.action_std

    @torch.no_grad()
    def select_action(self, batch: dict[str, Tensor], **kwargs) -> Tensor:
        """One action; a new chunk when the last one's ``n_action_steps`` are spent. Every
        observation is kept for the next chunk's history (the first repeated before it, as
        lerobot pads an episode's start)."""
        self.eval()
        now = {k: batch[k] for k in (OBS_STATE, OBS_ENV_STATE)}
        while len(self._seen) < self.config.n_obs_steps - 1:
            self._seen.append(now)
        self._seen.append(now)
        if not self._queue:
            frames = {k: torch.stack([seen[k] for seen in self._seen], dim=1) for k in now}
            chunk = self.predict_action_chunk(frames)[:, : self.config.n_action_steps]
            self._queue.extend(chunk.transpose(0, 1))
        return self._queue.popleft()
