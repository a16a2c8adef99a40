"""A ``cake_mlp`` that reads numbers only, acting in NumPy: no torch in the process.

A run or an evaluation worker that acts with the shipped state policy or the learned
skills needs the perceptron's forward pass and its action queue, nothing else; importing
torch for it costs more than the whole classical run (about 620 MB and 1.4 s on these
machines, against 290 MB and 1.4 s for a whole run). :class:`NumpyChunks` reads the same
checkpoint files (``config.json``, ``model.safetensors``) and does the same arithmetic as
:class:`cake_drake.learning.policies.mlp.network.Chunks` (tests/learning/test_mlp.py
compares them); a policy that sees keeps torch (its convolutions).
"""

from __future__ import annotations

import json
import math
import re
from collections import deque
from pathlib import Path

import numpy as np

from cake_drake.learning.policies.mlp.features import (
    ARM,
    EXTRA_INPUTS,
    OBS_STATE,
    camera_shapes,
    input_sizes,
)

_erf = np.frompyfunc(math.erf, 1, 1)


def _gelu(x: np.ndarray) -> np.ndarray:
    """torch's exact GELU, x * Phi(x)."""
    return x * 0.5 * (1.0 + _erf(x / math.sqrt(2.0)).astype(x.dtype))


class NumpyChunks:
    """The checkpoint in ``folder`` (a ``cake_mlp`` without cameras), acting: ``reset``,
    ``select_action`` and ``predict_action_chunk`` on NumPy arrays, batched (B, ...)."""

    def __init__(self, folder: Path, ensemble: float = 0.0) -> None:
        from safetensors.numpy import load_file  # safetensors: the lerobot extra's

        #: ACT's temporal ensembling (Zhao et al. 2023), 0: off. Above 0, a chunk is
        #: predicted at every step and each action is the weighted mean of every live
        #: chunk's prediction for that step, as ACT weighs them: exp(-ensemble * i),
        #: i = 0 the oldest chunk.
        self.ensemble = float(ensemble)
        folder = Path(folder)
        data = json.loads((folder / "config.json").read_text())
        self.n_obs_steps = int(data.get("n_obs_steps", 1))
        self.chunk_size = int(data.get("chunk_size", 10))
        self.n_action_steps = int(data.get("n_action_steps", 5))
        self.relative_joints = bool(data.get("relative_joints", True))
        weights = load_file(str(folder / "model.safetensors"))
        inputs = input_sizes(data["input_features"])
        self.input_keys = tuple(inputs)
        names = {OBS_STATE: "state", **EXTRA_INPUTS}
        self._stats = {
            key: (weights[f"{names[key]}_mean"], weights[f"{names[key]}_std"]) for key in inputs
        }
        self.action_mean, self.action_std = weights["action_mean"], weights["action_std"]
        self.action_dim = int(self.action_mean.shape[0])
        layers = sorted(
            int(m.group(1)) for k in weights if (m := re.fullmatch(r"net\.(\d+)\.weight", k))
        )
        self._layers = [(weights[f"net.{i}.weight"].T, weights[f"net.{i}.bias"]) for i in layers]
        self.reset()

    def reset(self) -> None:
        self._queue: deque[np.ndarray] = deque([], maxlen=self.n_action_steps)
        self._seen: deque[dict[str, np.ndarray]] = deque([], maxlen=self.n_obs_steps)
        #: Temporal ensembling: the chunks still covering a coming step, oldest first,
        #: each with how many of its actions have passed.
        self._chunks: deque[list] = deque([], maxlen=self.chunk_size)

    def predict_action_chunk(self, batch: dict[str, np.ndarray]) -> np.ndarray:
        """The chunk, (B, chunk_size, action_dim), for inputs (B, D) or (B, T, D)."""
        parts = []
        for key in self.input_keys:
            mean, std = self._stats[key]
            parts.append((np.asarray(batch[key], np.float32) - mean) / std)
        x = np.concatenate(parts, axis=-1)
        if x.ndim == 3:
            x = x.reshape(x.shape[0], -1)
        for k, (weight, bias) in enumerate(self._layers):
            x = x @ weight + bias
            if k < len(self._layers) - 1:
                x = _gelu(x)
        chunk = x.reshape(-1, self.chunk_size, self.action_dim)
        state = np.asarray(batch[OBS_STATE], np.float32)
        now = state if state.ndim == 2 else state[:, -1]
        origin = np.repeat(self.action_mean[None], now.shape[0], axis=0)
        if self.relative_joints:
            origin[:, :ARM] = now[:, :ARM]
        return origin[:, None, :] + chunk * self.action_std

    def select_action(self, batch: dict[str, np.ndarray]) -> np.ndarray:
        """One action (B, action_dim); a new chunk when the last one's are spent, from the
        observations seen (the first repeated before it, as LeRobot pads a start)."""
        now = {k: np.asarray(batch[k], np.float32) for k in self.input_keys}
        while len(self._seen) < self.n_obs_steps - 1:
            self._seen.append(now)
        self._seen.append(now)
        if self.ensemble > 0:
            frames = {k: np.stack([seen[k] for seen in self._seen], axis=1) for k in now}
            self._chunks.append([self.predict_action_chunk(frames), 0])
            rows = [chunk[:, used] for chunk, used in self._chunks]
            weights = np.exp(-self.ensemble * np.arange(len(rows)))
            action = np.tensordot(weights / weights.sum(), np.stack(rows), axes=1)
            for entry in self._chunks:
                entry[1] += 1
            while self._chunks and self._chunks[0][1] >= self.chunk_size:
                self._chunks.popleft()
            return action.astype(np.float32)
        if not self._queue:
            frames = {k: np.stack([seen[k] for seen in self._seen], axis=1) for k in now}
            chunk = self.predict_action_chunk(frames)[:, : self.n_action_steps]
            self._queue.extend(np.swapaxes(chunk, 0, 1))
        return self._queue.popleft()


class TorchActing:
    """A torch ``cake_mlp`` network (one that sees, or on a GPU) behind the same NumPy
    face as :class:`NumpyChunks`."""

    def __init__(self, network, device: str) -> None:
        self.network, self.device = network, device
        self.input_keys = (*network.input_keys, *network.cameras)

    def reset(self) -> None:
        self.network.reset()

    def select_action(self, batch: dict[str, np.ndarray]) -> np.ndarray:
        import torch  # loaded already: the network is torch's (load)

        with torch.inference_mode():
            tensors = {k: torch.as_tensor(batch[k]).to(self.device) for k in self.input_keys}
            return self.network.select_action(tensors).cpu().numpy()


def load(folder: Path, device: str = "cpu", ensemble: float = 0.0):
    """The ``cake_mlp`` checkpoint in ``folder``, acting on NumPy arrays: in NumPy when it
    reads numbers only and acts on the CPU, else through torch (``ensemble``, temporal
    ensembling: NumPy only)."""
    folder = Path(folder)
    inputs = json.loads((folder / "config.json").read_text())["input_features"]
    if device == "cpu" and not camera_shapes(inputs):
        return NumpyChunks(folder, ensemble)
    if ensemble:
        raise ValueError("temporal ensembling acts in NumPy: a cake_mlp without cameras, cpu")
    # torch (seconds) only for a network that reads cameras or acts on a GPU.
    from cake_drake.learning.policies.mlp.network import load as load_network

    return TorchActing(load_network(folder, device), device)
