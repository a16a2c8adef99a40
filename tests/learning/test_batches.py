"""The data path under LeRobot's loop (cake_drake.learning.data.batches): the same samples as
LeRobot's own dataset, read from memory, and no frame decoded for a policy that reads none.

Real recordings (Drake, lerobot's writer), LeRobot's own dataset and training loop.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from cake_drake.learning.data import batches
from tests.helpers import ROOT

DEMONSTRATIONS = ROOT / "models" / "scenarios" / "demonstrations.yaml"
REPO_ID = "cake_drake/stack"

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    """Three episodes of the small task, with its two cameras (64 x 64 and 48 x 48)."""
    out = tmp_path_factory.mktemp("batches") / "ds"
    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.record", str(DEMONSTRATIONS), "--name", "small",
         "--episodes", "3", "--workers", "1", "--out", str(out)],
        cwd=ROOT, capture_output=True, text=True, timeout=600,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    return out


def lerobot(root: Path, deltas: dict):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    return LeRobotDataset(REPO_ID, root=root, delta_timestamps=deltas, video_backend="pyav")


def assert_same(a: dict, b: dict, where: str) -> None:
    assert set(a) == set(b), (where, set(a) ^ set(b))
    for key, value in a.items():
        if isinstance(value, torch.Tensor):
            assert value.dtype == b[key].dtype and value.shape == b[key].shape, (where, key)
            assert torch.equal(value, b[key]), (where, key)
        else:
            assert value == b[key], (where, key)


HISTORY_AND_CHUNKS = {
    "observation.state": [-0.2, -0.1, 0.0],
    "observation.environment_state": [-0.1, 0.0],
    "observation.images.scene": [-0.1, 0.0],
    "observation.images.wrist": [0.0],
    "action": [k / 10 for k in range(10)],
}


@pytest.mark.parametrize("deltas", [None, HISTORY_AND_CHUNKS], ids=["frames", "history"])
def test_the_columns_give_lerobots_samples(recording, deltas):
    """Every key LeRobot gives, the same tensors (dtype, shape, values) and padding flags,
    the cameras' frames included, at an episode's first and last frames and in between."""
    base = lerobot(recording, deltas)
    fast = batches.ColumnDataset(base, None)
    assert len(fast) == len(base)
    ends = base.meta.episodes["dataset_to_index"]
    rows = sorted({0, 1, 2, ends[0] - 1, ends[0], ends[0] + 1, ends[1] - 2, len(base) - 1, 57})
    for i in rows:
        assert_same(base[i], fast[i], f"row {i}")
    if deltas:  # an episode's edges are padded as LeRobot pads them
        assert fast[0]["observation.state_is_pad"].tolist() == [True, True, False]
        assert fast[len(base) - 1]["action_is_pad"].sum() == 9
    together = fast.__getitems__(rows)
    for i, item in zip(rows, together, strict=True):
        assert_same(base[i], item, f"row {i} in a batch")


def test_a_policy_that_reads_no_camera_decodes_no_frame(recording, monkeypatch):
    """A state policy on a recording with cameras: no frame decoded (counted), and no
    camera in its samples; a policy that reads one camera decodes that camera alone."""
    decoded = []
    original = batches.decode_all
    monkeypatch.setattr(batches, "decode_all", lambda path: decoded.append(path) or original(path))
    base = lerobot(recording, {"observation.state": [-0.1, 0.0], "action": [0.0, 0.1]})
    fast = batches.ColumnDataset(base, ["observation.state", "observation.environment_state"])
    items = fast.__getitems__(list(range(len(fast))))
    assert decoded == []
    assert not any(k.startswith("observation.images.") and "_is_pad" not in k for k in items[0])
    reading = batches.ColumnDataset(base, ["observation.state", "observation.images.wrist"])
    assert len(decoded) == 1 and list(reading.frames) == ["observation.images.wrist"]
    assert reading.frames["observation.images.wrist"].dtype.name == "uint8"  # kept as bytes


def test_train_reads_through_the_columns(recording, tmp_path, monkeypatch):
    """cake_drake.train's LeRobot loop iterates ColumnDataset (no loader workers), and its
    checkpoint is written."""
    from cake_drake.learning.training.train import recipe_of, train

    made = []
    original = batches.ColumnDataset.__init__

    def seen(self, base, keys=None):
        made.append(keys)
        original(self, base, keys)

    monkeypatch.setattr(batches.ColumnDataset, "__init__", seen)
    recipe, _ = recipe_of(recording)
    recipe.policy, recipe.steps, recipe.batch_size = "mlp", 3, 8
    recipe.hidden_dims, recipe.n_obs_steps, recipe.chunk_size = [16], 2, 4
    recipe.n_action_steps = 4
    folder = train(recording, tmp_path / "run", recipe, device="cpu")
    assert (folder / "model.safetensors").is_file()
    assert made == [["observation.state", "observation.environment_state"]]
    # Where the time went, kept for the benchmark's profile line: each phase measured, and
    # the loop's parts within the whole loop.
    phases = json.loads((tmp_path / "run" / "train.json").read_text())["phases_s"]
    assert set(phases) == {"loading", "batches", "network", "checkpoint", "train"}
    assert all(phases[k] > 0 for k in phases)
    assert phases["batches"] + phases["network"] + phases["checkpoint"] < phases["train"]


def test_cameras_of_two_sizes_are_refused_where_the_policy_needs_one(recording, tmp_path):
    """Diffusion Policy stacks its cameras: the small task's 96 x 96 and 64 x 64 are one
    line, exit 2, before anything is read; the project's mlp has an encoder a camera."""
    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.train", str(recording), "--out", str(tmp_path / "d"),
         "--policy", "diffusion", "--inputs", "images"],
        cwd=ROOT, capture_output=True, text=True, timeout=300,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "Diffusion Policy needs its cameras at one size; these are scene 96x96, wrist 64x64" in (
        r.stderr
    )
    assert not (tmp_path / "d").exists()
