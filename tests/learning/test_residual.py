"""The learned bottom: a world the controller's model gets wrong on purpose, the residual's
labels, its fit, the shipped residual in a run, and what is refused.

Real Drake runs throughout (a few seconds each).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cake_drake.dynamic.residual import Kinematics, ResidualModel, samples
from cake_drake.errors import InputError
from cake_drake.learning.training.residual import train_residual
from cake_drake.pipeline import run
from cake_drake.scenario import ComputedTorque, Generate, Scenario
from cake_drake.world.scene import make_control_plant
from tests.helpers import ROOT

EXERCISE = ROOT / "models" / "scenarios" / "exercise.yaml"


def heavy(tmp: Path | None, **world) -> Scenario:
    s = Scenario(controller=ComputedTorque())
    s.task.generate = Generate(blocks=3, seed=11)
    for key, value in world.items():
        setattr(s.world, key, value)
    s.outputs.render = False
    if tmp is not None:
        s.outputs.folder, s.outputs.logs = str(tmp), True
    return s


def cake(*args: str, cwd: Path):
    return subprocess.run(
        [sys.executable, "-m", *args], cwd=cwd, capture_output=True, text=True, timeout=300,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip


@pytest.mark.slow
def test_the_label_is_the_unmodelled_payload():
    """A 0.3 kg payload at the grasp frame, which the model lacks: while the hand is open
    (nothing else in it), the label is the payload's weight and inertia, m J^T (g + J a),
    computed from the plant's own kinematics, within 5 % on the shoulder and the elbow."""
    result = run(heavy(None, payload_kg=0.3), write=False)
    logs = result.execution.logs
    kin = Kinematics(make_control_plant())
    phi, label = samples(logs, kin)
    a = np.diff(logs.v, axis=0) / np.diff(logs.t)[:, None]
    expected = []
    for k in range(len(a)):
        gravity, inertia = kin.terms(logs.q[k], a[k])
        expected.append(0.3 * (gravity + inertia))
    expected = np.array(expected)
    empty = logs.fingers[:-1] > 0.035  # the fingers open: the payload alone
    assert empty.sum() > 200
    err = np.median(np.abs(label[empty] - expected[empty])[:, [1, 3]], axis=0)
    size = np.median(np.abs(expected[empty])[:, [1, 3]], axis=0)
    assert size.min() > 0.1 and np.all(err < 0.05 * size), (err, size)


@pytest.mark.slow
def test_a_residual_fitted_on_one_run_cuts_the_error_of_its_held_out_part(tmp_path, monkeypatch):
    run(heavy(tmp_path / "run", cube_mass_kg=0.5))
    # A fit that gives no numbers (forced here, as degenerate samples would) is refused
    # in one line and never written.
    import cake_drake.learning.training.residual as residual_fit

    real_fit = residual_fit.fit
    monkeypatch.setattr(residual_fit, "fit", lambda phi, y: real_fit(phi, y) * np.nan)
    with pytest.raises(InputError, match="the fit gave no finite weights"):
        train_residual([tmp_path / "run"], tmp_path / "nan")
    assert not (tmp_path / "nan").exists()
    monkeypatch.setattr(residual_fit, "fit", real_fit)
    fit = train_residual([tmp_path / "run"], tmp_path / "residual")
    before = np.asarray(fit["held_out_rms_nm_before"])
    after = np.asarray(fit["held_out_rms_nm_after"])
    assert np.all(after < before), (before, after)  # every joint, held-out samples held
    model = ResidualModel.load(tmp_path / "residual")
    assert np.asarray(model.weights).shape == (7, 5)
    assert (tmp_path / "residual" / "residual.json").stat().st_size < 1_000_000


@pytest.mark.slow
def test_the_shipped_residual_builds_the_tower_the_uncorrected_run_drops(tmp_path):
    """The documented pair: heavy cubes uncorrected fail (exit 3), with the shipped
    residual the tower stands, and the summary labels the dynamic layer learned."""
    r = cake("cake_drake.run", "--scenario", str(EXERCISE), "--name", "heavy_cubes", "--out",
             "heavy", cwd=tmp_path)  # fmt: skip
    assert r.returncode == 3, r.stderr
    r = cake("cake_drake.run", "--scenario", str(EXERCISE), "--name", "residual", "--out",
             "residual", cwd=tmp_path)  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "goal reached: a on b on c on d on e" in r.stdout
    summary = json.loads((tmp_path / "residual" / "summary.json").read_text())
    assert summary["layers"]["dynamic"]["kind"] == "learned"
    assert "cubes_0.5kg" in summary["layers"]["dynamic"]["what"]
    assert summary["layers"]["symbolic"] == {"kind": "classical", "what": "astar-lmcut"}
    # The wrist (joint 6) stays within 60 mrad, where uncorrected it reaches 0.13 rad.
    assert summary["tracking_error"]["max_rad"][5] < 0.06, summary["tracking_error"]
    uncorrected = json.loads((tmp_path / "heavy" / "summary.json").read_text())
    assert uncorrected["tracking_error"]["max_rad"][5] > 0.1


@pytest.mark.parametrize(
    "yaml, words",
    [
        ("controller: !ComputedTorque {residual: other}\n", "no residual here"),
        ("controller: !ComputedTorque {residual: six}\n", "for 6 joints"),
        ("world: {cube_mass_kg: 5.0}\n", "world.cube_mass_kg = 5.0 is outside 0.01 to 1"),
        ("world: {joint_friction: [0.1, 0.2]}\n", "world.joint_friction takes one value or seven"),
        ("controller: !JointPd {residual: six}\n", "residual"),
    ],
)
def test_bad_residual_input_is_one_line_before_anything_runs(tmp_path, yaml, words):
    six = ResidualModel(weights=[[0.0] * 5] * 7)
    six.joints = 6
    six.save(tmp_path / "six")
    (tmp_path / "s.yaml").write_text(yaml)
    r = cake("cake_drake.run", "--scenario", "s.yaml", "--out", "out", cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and words in r.stderr, r.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_the_defaults_are_the_world_as_it_was(tmp_path):
    """The mismatch fields at their defaults change no bit of the exercise's run: the
    cubes' final poses and the tracking error are those of the run before they existed."""
    before = json.loads((ROOT / "tests" / "data" / "default_torque_summary.json").read_text())
    s = Scenario(controller=ComputedTorque())
    s.outputs.folder, s.outputs.render = str(tmp_path), False
    run(s)
    now = json.loads((tmp_path / "summary.json").read_text())
    assert now["blocks"] == before["blocks"]
    assert now["tracking_error"] == before["tracking_error"]
