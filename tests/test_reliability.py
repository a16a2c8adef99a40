"""The learned layers' files and answers, damaged as users damage them: each class of
damage is one line naming the file or the plug-in, a documented exit code, and nothing
half-written (the rest of the classes live beside their loaders' tests)."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cake_drake.errors import EXIT_EXECUTION_FAILED
from cake_drake.pipeline import run
from cake_drake.plugins import PluginError
from cake_drake.scenario import PACKAGE, Scenario, portable_path

ROOT = Path(__file__).resolve().parent.parent


def _cli(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=600)  # fmt: skip


def test_a_package_path_is_written_as_given_not_joined_to_the_working_folder(tmp_path):
    shipped = PACKAGE + "policies/skills"
    assert portable_path(shipped) == shipped
    assert portable_path(ROOT / "models" / "policies" / "skills") == shipped
    assert portable_path(tmp_path) == str(tmp_path.resolve())


def test_skills_beside_a_whole_task_policy_are_refused_in_one_line(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text(
        "both:\n"
        "  reference: !Policy {checkpoint: package://cake_drake/policies/stack2}\n"
        "  motion: {skills: package://cake_drake/policies/skills}\n"
    )
    r = _cli("cake_drake.run", "--scenario", str(path), "--name", "both",
             "--out", str(tmp_path / "out"))  # fmt: skip
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1
    assert "motion.skills (package://cake_drake/policies/skills) with reference: !Policy" in (
        r.stderr
    )
    assert not (tmp_path / "out").exists()


def test_the_classical_monitor_stops_an_action_that_fails_three_times_in_a_row():
    # The heaviest world the fields allow: the arm cannot lift a 1 kg cube with 2 kg of
    # payload in its hand, so the pick is repeated, and the run stops at the third try.
    s = Scenario()
    s.world.cube_mass_kg, s.world.payload_kg = 1.0, 2.0
    result = run(s, write=False)
    assert not result.success
    assert "failed 3 times in a row" in result.message, result.message
    events = result.execution.monitoring["events"]
    assert sum(e["kind"] == "repeat" for e in events) >= 3
    assert result.execution.sim_s < 30.0  # not the whole simulated budget


class _HangingSkill:
    """A skill that answers far slower than its budget (a hung model, a lock)."""

    act_budget_s = 0.5

    def reset(self):
        pass

    def act(self, observation):
        time.sleep(30)
        return np.zeros(8)


def hanging_skill(path, device):
    return _HangingSkill()


def _no_check(path, device):
    return None


def test_a_skill_that_hangs_is_stopped_at_its_budget_naming_it(monkeypatch, tmp_path):
    monkeypatch.setattr("cake_drake.scenario.SKILL_POLICY", f"{__name__}:hanging_skill")
    monkeypatch.setattr("cake_drake.pipeline.SKILL_CHECK", f"{__name__}:_no_check")
    monkeypatch.syspath_prepend(str(Path(__file__).parent))
    s = Scenario()
    s.motion.skills = str(tmp_path)
    t0 = time.monotonic()
    with pytest.raises(PluginError) as e:
        run(s, write=False)
    assert time.monotonic() - t0 < 25
    assert e.value.exit_code == EXIT_EXECUTION_FAILED
    assert f"skill '{tmp_path.resolve()}'" in str(e.value) and "0.5 s" in str(e.value)


def test_the_lerobot_env_offers_only_learning_tasks():
    from cake_drake.learning.lerobot_env import CakeDrakeEnv

    with pytest.raises(ValueError) as e:
        CakeDrakeEnv(task="learned_tower5")
    offered = str(e.value).split("choose one of: ")[1].split(", ")
    assert offered == ["stack2", "tower3", "tower5", "blocks3", "skills"]
    assert CakeDrakeEnv(task="tower3").task == "tower3"
