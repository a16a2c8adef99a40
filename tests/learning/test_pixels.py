"""A policy that sees: recorded with cameras, trained on the cameras and the joints (no
cube pose), evaluated and run with the cameras it was trained on, and refused without
them.

Real recordings (Drake's renderer, lerobot's writer), LeRobot's own training loop, the
project's evaluate and run.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers import ROOT

LEARNING = ROOT / "models" / "scenarios" / "learning.yaml"

pytestmark = pytest.mark.slow


def cake(command: str, *args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", f"cake_drake.{command}", *args],
        cwd=cwd, capture_output=True, text=True, timeout=900,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip


@pytest.fixture(scope="module")
def seeing(tmp_path_factory) -> Path:
    """stack2: two episodes recorded with the task's two cameras, then a few steps of an
    image policy (--inputs images)."""
    folder = tmp_path_factory.mktemp("pixels")
    r = cake("record", str(LEARNING), "--name", "stack2", "--out", str(folder / "ds"),
             "--episodes", "2", "--workers", "1")  # fmt: skip
    assert r.returncode == 0, r.stderr
    r = cake("train", str(folder / "ds"), "--out", str(folder / "run"), "--inputs", "images",
             "--steps", "3", "--batch-size", "4", "--device", "cpu")  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "mlp (images) trained 3 steps" in r.stdout
    return folder


def config(run: Path) -> dict:
    model = run / "checkpoints" / "last" / "pretrained_model"
    return json.loads((model / "config.json").read_text())


def test_the_image_policys_inputs_hold_no_pose(seeing):
    features = config(seeing / "run")["input_features"]
    assert set(features) == {
        "observation.state",
        "observation.goal",
        "observation.images.scene",
        "observation.images.wrist",
    }
    assert features["observation.images.wrist"]["shape"] == [3, 96, 96]
    assert features["observation.goal"]["shape"] == [156]  # the goal table, no pose
    recipe = json.loads((seeing / "run" / "train.json").read_text())["recipe"]
    assert recipe["inputs"] == "images" and recipe["batch_size"] == 4


def test_one_camera_is_trained_on_alone_and_an_unknown_one_is_refused(seeing, tmp_path):
    r = cake("train", str(seeing / "ds"), "--out", str(tmp_path / "wrist"), "--inputs",
             "images", "--cameras", "wrist", "--steps", "2", "--batch-size", "4",
             "--device", "cpu")  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert [k for k in config(tmp_path / "wrist")["input_features"] if "images" in k] == [
        "observation.images.wrist"
    ]
    r = cake("train", str(seeing / "ds"), "--out", str(tmp_path / "x"), "--inputs", "images",
             "--cameras", "top", "--steps", "2")  # fmt: skip
    assert r.returncode == 2
    assert r.stderr.strip().endswith("has no such camera; it has scene, wrist")
    r = cake("train", str(seeing / "ds"), "--out", str(tmp_path / "y"), "--cameras", "wrist",
             "--steps", "2")  # fmt: skip
    assert r.returncode == 2 and "the cameras are read with --inputs images" in r.stderr
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()


def test_evaluate_and_a_run_give_it_its_cameras(seeing, tmp_path):
    r = cake("evaluate", str(seeing / "run"), "--suite", str(LEARNING), "--name", "stack2",
             "--episodes", "1", "--seed", "100000", "--workers", "1", "--out",
             str(tmp_path / "ev"))  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "ev" / "summary.json").read_text())["episodes"] == 1
    cameras = (
        "cameras:\n  - {name: scene, width: 96, height: 96}\n"
        "  - {name: wrist, attached_to: panda_hand, xyz: [0.09, 0.0, 0.02], "
        "target: [0.0, 0.0, 0.2], width: 96, height: 96, fov_y_deg: 70.0}\n"
    )
    (tmp_path / "s.yaml").write_text(
        'task: {problem: "package://cake_drake/pddl/stack2.pddl"}\n'
        f"reference: !Policy {{checkpoint: {seeing / 'run'}, max_steps: 3}}\n"
        "outputs: {render: false}\n" + cameras
    )
    r = cake("run", "--scenario", "s.yaml", "--out", "out", cwd=tmp_path)
    assert r.returncode == 3 and "step budget of 3" in r.stderr  # it ran, and acted


@pytest.mark.parametrize(
    "cameras, words",
    [
        ("cameras: []\n", "the policy sees camera 'scene', which the scenario lacks"),
        (
            "cameras:\n  - {name: scene, width: 64, height: 64}\n  - {name: wrist}\n",
            "saw camera 'scene' at 96 x 96; the scenario's is 64 x 64",
        ),
    ],
    ids=["none", "other-size"],
)
def test_a_run_without_the_trained_cameras_is_refused_before_simulating(
    seeing, tmp_path, cameras, words
):
    (tmp_path / "s.yaml").write_text(
        'task: {problem: "package://cake_drake/pddl/stack2.pddl"}\n'
        f"reference: !Policy {{checkpoint: {seeing / 'run'}}}\n" + cameras
    )
    r = cake("run", "--scenario", "s.yaml", "--out", "out", cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert words in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_the_shipped_pixel_policy_stacks_on_its_documented_seed(tmp_path):
    """models/policies/stack2_pixels reads no pose, and learned_stack2_pixels (its held-out
    seed, the task's cameras) stacks offline; its last frames are among the outputs."""
    shipped = ROOT / "models" / "policies" / "stack2_pixels"
    features = json.loads((shipped / "config.json").read_text())["input_features"]
    assert "observation.environment_state" not in features
    assert {"observation.images.scene", "observation.images.wrist"} <= set(features)
    assert sum(f.stat().st_size for f in shipped.iterdir()) < 10_000_000
    r = cake("run", "--scenario", str(LEARNING), "--name", "learned_stack2_pixels", "--out",
             str(tmp_path / "out"))  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "goal reached: a on b" in r.stdout + r.stderr
    assert "geometric learned" in r.stdout + r.stderr
    for name in ("final_state.png", "camera_scene.png", "camera_wrist.png"):
        assert (tmp_path / "out" / name).stat().st_size > 1000


def test_the_picture_of_what_it_saw_is_drawn(tmp_path):
    """benchmarks/seeing.py runs the shipped policy on its held-out seed and draws it."""
    r = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "seeing.py"), "--seed", "100001", "--out",
         str(tmp_path / "saw.png")],
        cwd=ROOT, capture_output=True, text=True, timeout=900,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "stack2, seed 100001: goal reached" in r.stdout
    assert (tmp_path / "saw.png").stat().st_size > 10_000
