"""The ``cake_mlp`` policy's network and action queue in torch alone, without LeRobot.

:class:`Chunks` holds the policy's arithmetic: standardised inputs over the last
``n_obs_steps`` observations, a chunk of ``chunk_size`` actions out (the arm's joints as
offsets from the measured ones), ``n_action_steps`` of them served before the next
chunk. A policy that sees reads each camera's latest frame through a small encoder of
its own (:class:`Vision`), whose keypoints join the numbers the perceptron reads.
LeRobot's wrapper (:class:`cake_drake.learning.policies.mlp.modeling_mlp.CakeMLPPolicy`)
trains it through LeRobot's loop; :func:`load` builds the same network from a checkpoint
folder (its ``config.json`` and ``model.safetensors``, the same weights under the same
names) for a run or an evaluation to act with, without importing LeRobot's policies
(which bring torchvision, diffusers and every other policy type: seconds a process).
"""

from __future__ import annotations

import json
from collections import deque
from pathlib import Path
from types import SimpleNamespace

import torch
from torch import Tensor, nn

from cake_drake.learning.policies.mlp.features import (
    ACTION,
    ARM,
    EXTRA_INPUTS,
    OBS_IMAGES,
    OBS_STATE,
    camera_shapes,
    input_sizes,
)


def random_shift(images: Tensor, pad: int) -> Tensor:
    """Each image of the batch (B, C, H, W) moved by its own whole number of pixels, up to
    ``pad`` in x and in y, its border repeated: the augmentation image policies need
    (a cube seen one pixel off is the same cube). The labels are not touched."""
    if pad <= 0:
        return images
    b, _, h, w = images.shape
    padded = nn.functional.pad(images, (pad, pad, pad, pad), mode="replicate")
    moves = torch.randint(0, 2 * pad + 1, (b, 2)).tolist()
    # A slice a sample: about ten times quicker than one gather over the batch.
    return torch.stack([padded[k, :, y : y + h, x : x + w] for k, (y, x) in enumerate(moves)])


class Vision(nn.Module):
    """One camera's encoder: four 3x3 convolutions (strides 2, 2, 1, 1), then a spatial
    softmax: for each of ``keypoints`` feature maps, where in the image it is most active,
    as an expected (x, y) in [-1, 1]. Keypoints say where the cubes and the fingers are,
    which is what a policy that places a cube needs; ``2 * keypoints`` numbers out."""

    def __init__(self, channels: int, keypoints: int, height: int, width: int) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        width_in = 3
        for stride in (2, 2, 1, 1):
            layers += [nn.Conv2d(width_in, channels, 3, stride=stride), nn.ReLU()]
            width_in = channels
        layers.append(nn.Conv2d(channels, keypoints, 1))
        self.convs = nn.Sequential(*layers)
        with torch.no_grad():
            h, w = self.convs(torch.zeros(1, 3, height, width)).shape[-2:]
        ys, xs = torch.meshgrid(torch.linspace(-1, 1, h), torch.linspace(-1, 1, w), indexing="ij")
        grid = torch.stack([xs.flatten(), ys.flatten()], -1)
        self.register_buffer("grid", grid, persistent=False)

    def forward(self, images: Tensor) -> Tensor:
        maps = self.convs(images).flatten(2)  # (B, K, h*w)
        attention = torch.softmax(maps, dim=-1)
        return (attention @ self.grid).flatten(1)  # (B, 2K): x, y of each keypoint


def _stats(stats: dict | None, key: str, size: int, floor: float) -> tuple[Tensor, Tensor]:
    """Mean and floored spread of feature ``key`` (zeros and ones when there are none: a
    policy loaded from a checkpoint gets its statistics from the weights)."""
    if stats and key in stats:
        mean = torch.as_tensor(stats[key]["mean"], dtype=torch.float32).reshape(size)
        std = torch.as_tensor(stats[key]["std"], dtype=torch.float32).reshape(size)
        return mean, std.clamp_min(floor)
    return torch.zeros(size), torch.ones(size)


class Chunks:
    """The policy's arithmetic, mixed into an ``nn.Module`` with a ``config`` (the fields
    of :class:`cake_drake.learning.policies.mlp.configuration_mlp.CakeMLPConfig`)."""

    def build(
        self, config, inputs: dict[str, int], action_dim: int, stats=None, cameras=None
    ) -> None:
        """The statistics (buffers, saved with the weights) and the layers, for ``inputs``
        (:func:`input_sizes`: ``observation.state`` and one or more of
        :data:`EXTRA_INPUTS`) and ``cameras`` (:func:`camera_shapes`)."""
        self.config = config
        self.action_dim = action_dim
        cameras = dict(cameras or {})
        if OBS_STATE not in inputs or len(inputs) + len(cameras) < 2:
            raise ValueError(
                "cake_mlp reads observation.state and "
                + " or ".join([*EXTRA_INPUTS, "cameras"])
                + f"; the features are {', '.join([*inputs, *cameras]) or 'none'}"
            )  # fmt: skip
        if config.relative_joints and (action_dim < ARM or inputs[OBS_STATE] < ARM):
            raise ValueError("relative_joints needs 7 arm joints in the state and the action")
        self.input_keys = tuple(inputs)
        names = {OBS_STATE: "state", **EXTRA_INPUTS, ACTION: "action"}
        for key, size in (*inputs.items(), (ACTION, action_dim)):
            mean, std = _stats(stats, key, size, config.min_std)
            self.register_buffer(f"{names[key]}_mean", mean)
            self.register_buffer(f"{names[key]}_std", std)
        self._buffers_of = {key: names[key] for key in inputs}
        self.cameras = tuple(cameras)
        self.vision = nn.ModuleDict()
        for key, (channels, height, width) in cameras.items():
            name = key[len(OBS_IMAGES) :]
            mean, std = _stats(stats, key, channels, 1e-3)
            self.register_buffer(f"image_{name}_mean", mean.reshape(channels, 1, 1))
            self.register_buffer(f"image_{name}_std", std.reshape(channels, 1, 1))
            self.vision[name] = Vision(
                config.vision_channels, config.vision_keypoints, height, width
            )
        layers: list[nn.Module] = []
        width = sum(inputs.values()) * config.n_obs_steps
        width += 2 * config.vision_keypoints * len(cameras)
        for hidden in config.hidden_dims:
            layers += [nn.Linear(width, hidden), nn.GELU()]
            if config.dropout:
                layers.append(nn.Dropout(config.dropout))
            width = hidden
        layers.append(nn.Linear(width, config.chunk_size * action_dim))
        self.net = nn.Sequential(*layers)
        self.reset()

    def reset(self) -> None:
        self._queue: deque[Tensor] = deque([], maxlen=self.config.n_action_steps)
        self._seen: deque[dict[str, Tensor]] = deque([], maxlen=self.config.n_obs_steps)

    def _inputs(self, batch: dict[str, Tensor]) -> Tensor:
        """The standardised observations, oldest first, side by side: (B, n_obs_steps * D)."""
        parts = []
        for key in self.input_keys:
            name = self._buffers_of[key]
            mean, std = getattr(self, f"{name}_mean"), getattr(self, f"{name}_std")
            parts.append((batch[key] - mean) / std)
        x = torch.cat(parts, dim=-1)
        if x.dim() == 3:  # (B, n_obs_steps, D): the frames before the current one
            x = x.flatten(1)
        if self.training and self.config.input_noise:
            x = x + self.config.input_noise * torch.randn_like(x)
        if not self.cameras:
            return x
        seen = [x]
        for key in self.cameras:
            name = key[len(OBS_IMAGES) :]
            images = batch[key]
            if images.dim() == 5:  # (B, n_obs_steps, C, H, W): the latest frame is read
                images = images[:, -1]
            mean, std = getattr(self, f"image_{name}_mean"), getattr(self, f"image_{name}_std")
            images = (images - mean) / std
            if self.training:
                images = random_shift(images, self.config.crop_shift)
            seen.append(self.vision[name](images))
        return torch.cat(seen, dim=-1)

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

    @torch.no_grad()
    def predict_action_chunk(self, batch: dict[str, Tensor], **kwargs) -> Tensor:
        self.eval()
        return self._origin(batch) + self._chunk(batch) * self.action_std

    @torch.no_grad()
    def select_action(self, batch: dict[str, Tensor], **kwargs) -> Tensor:
        """One action; a new chunk when the last one's ``n_action_steps`` are spent. Every
        observation is kept for the next chunk's history (the first repeated before it, as
        LeRobot pads an episode's start)."""
        self.eval()
        now = {k: batch[k] for k in (*self.input_keys, *self.cameras)}
        while len(self._seen) < self.config.n_obs_steps - 1:
            self._seen.append(now)
        self._seen.append(now)
        if not self._queue:
            frames = {k: torch.stack([seen[k] for seen in self._seen], dim=1) for k in now}
            chunk = self.predict_action_chunk(frames)[:, : self.config.n_action_steps]
            self._queue.extend(chunk.transpose(0, 1))
        return self._queue.popleft()


class CakeMLPNetwork(Chunks, nn.Module):
    """The network alone, built from a checkpoint's configuration (:func:`load`)."""

    def __init__(self, config, inputs: dict[str, int], action_dim: int, cameras=None) -> None:
        nn.Module.__init__(self)
        self.build(config, inputs, action_dim, cameras=cameras)


def load(folder: Path, device: str = "cpu") -> CakeMLPNetwork:
    """The ``cake_mlp`` checkpoint in ``folder`` as a :class:`CakeMLPNetwork`."""
    from safetensors.torch import load_file  # safetensors: the lerobot extra's

    folder = Path(folder)
    data = json.loads((folder / "config.json").read_text())
    config = SimpleNamespace(**{
        k: data.get(k, default) for k, default in (
            ("n_obs_steps", 1), ("chunk_size", 10), ("n_action_steps", 5),
            ("hidden_dims", [512, 512, 512]), ("dropout", 0.0), ("relative_joints", True),
            ("min_std", 0.01), ("input_noise", 0.0), ("vision_channels", 32),
            ("vision_keypoints", 32), ("crop_shift", 4),
        )
    })  # fmt: skip
    inputs, outputs = data["input_features"], data["output_features"]
    action = int(outputs[ACTION]["shape"][0])
    network = CakeMLPNetwork(config, input_sizes(inputs), action, camera_shapes(inputs))
    network.load_state_dict(load_file(str(folder / "model.safetensors")), strict=True)
    return network.to(device).eval()
