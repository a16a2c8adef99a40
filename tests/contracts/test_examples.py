"""Every example plug-in (examples/) runs end to end through the same door a user's would."""

from __future__ import annotations

import subprocess
import sys

import pytest

from cake_drake.errors import NoPlanError
from cake_drake.pipeline import run
from cake_drake.scenario import load_scenario, scenario_names
from tests.helpers import ROOT

EXAMPLES = ROOT / "models" / "scenarios" / "examples.yaml"


def test_every_example_file_has_a_scenario():
    files = {p.stem for p in (ROOT / "examples").glob("*.py")}
    text = EXAMPLES.read_text()
    assert files == set(scenario_names(EXAMPLES))
    assert all(f"examples.{f}:" in text for f in files)


#: The examples that are meant to fail (a baseline the success measure must be able to fail).
FAILING = {"random_policy"}


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n in scenario_names(EXAMPLES) if n not in FAILING])
def test_example_plugin_builds_the_tower(name, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)  # what an example writes stays out of the checkout
    monkeypatch.syspath_prepend(str(ROOT))
    result = run(load_scenario(EXAMPLES, name), write=False)
    assert result.success, result.message
    assert {("on", "a", "b"), ("on", "d", "e")} <= result.execution.reading.facts


@pytest.mark.slow
def test_the_policy_chooses_its_own_actions(monkeypatch):
    monkeypatch.chdir(ROOT)
    result = run(load_scenario(EXAMPLES, "greedy_policy"), write=False)
    assert result.success, result.message
    assert result.cake.reference.action_source.get_name() == "action_source"
    assert type(result.cake.reference.action_source).__name__ == "GreedyTowerPolicy"


def test_a_wrong_answer_from_the_language_model_is_refused_before_the_robot_moves(
    monkeypatch, tmp_path
):
    monkeypatch.chdir(ROOT)
    import examples.language_planner as planner

    (tmp_path / "problem-5.txt").write_text("Robot: 1. pick up a, 2. stack a on e, 3. done")
    monkeypatch.setattr(planner, "ANSWERS", tmp_path)
    with pytest.raises(NoPlanError, match="step 1"):
        run(load_scenario(EXAMPLES, "language_planner"), write=False)


def test_the_language_planner_splits_numbered_steps():
    sys.path.insert(0, str(ROOT))
    from examples.language_planner import steps, to_action

    assert steps("Robot: 1. unstack a from b, 2.put down a,3) done") == [
        "unstack a from b",
        "put down a",
        "done",
    ]
    assert str(to_action("stack the c onto d")) == "(stack c d)"


@pytest.mark.slow
def test_the_recording_ik_keeps_every_query(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(ROOT))
    import examples.recording_ik as recording

    result = run(load_scenario(EXAMPLES, "recording_ik"), write=False)
    assert result.success, result.message
    solver = recording.MADE[-1]
    # A pick: three waypoints. A place: three planned up front, the place and retract
    # again above the target, and again at the release.
    picks = sum(a.name in ("pick-up", "unstack") for a in result.plan.actions)
    places = len(result.plan.actions) - picks
    assert len(solver.answers) == len(result.cake.ik.times_ms) == 3 * picks + 7 * places
    solver.save(tmp_path / "ik.npz")
    assert (tmp_path / "ik.npz").stat().st_size > 1000


@pytest.mark.slow
def test_an_example_runs_from_the_command_line(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.run", "--quiet", "--no-render",
         "--scenario", str(EXAMPLES), "--name", "residual_controller", "--out", str(tmp_path)],
        capture_output=True, text=True, cwd=ROOT,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "computed-torque+residual" in (tmp_path / "summary.json").read_text()


@pytest.mark.parametrize("name", sorted(FAILING))
def test_the_baseline_examples_do_not_build_the_tower(name, monkeypatch):
    monkeypatch.chdir(ROOT)
    result = run(load_scenario(EXAMPLES, name), write=False)
    assert not result.success


@pytest.mark.slow
def test_the_recording_ik_leaves_its_queries_from_the_command_line(tmp_path):
    import numpy as np

    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.run", "--ik", "examples.recording_ik:make",
         "--out", "o", "--no-render", "--quiet"],
        cwd=tmp_path, capture_output=True, text=True, timeout=600,
        env={**__import__("os").environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    with np.load(tmp_path / "ik_queries.npz") as z:
        assert z["X_WG"].shape[1:] == (4, 4) and len(z["q"]) == len(z["solved"]) > 10
        assert z["solved"].all() and np.isfinite(z["q"]).all()
