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
from tests.helpers import ROOT


def _cli(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=600)  # fmt: skip


def test_a_package_path_is_written_as_given_not_joined_to_the_working_folder(tmp_path):
    shipped = PACKAGE + "policies/skills"
    assert portable_path(shipped) == shipped
    assert portable_path(ROOT / "models" / "policies" / "skills") == shipped
    assert portable_path(tmp_path) == str(tmp_path.resolve())


@pytest.mark.parametrize(
    "field, value",
    [
        ("task.problem", "package://cake_drake/../../../etc/passwd"),
        ("task.problem", "package://cake_drake/pddl/../../../../etc/passwd"),
        ("motion.skills", "package://cake_drake/../../../etc"),
    ],
)
def test_a_package_url_out_of_models_is_refused_unread(tmp_path, field, value):
    section, name = field.split(".")
    path = tmp_path / "s.yaml"
    path.write_text(f"{section}: {{{name}: '{value}'}}\n")
    r = _cli("cake_drake.run", "--scenario", str(path), "--out", str(tmp_path / "out"))
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and "refused unread" in r.stderr, r.stderr
    assert "root:" not in r.stderr  # nothing of the file is quoted back


@pytest.mark.parametrize(
    "value, words",
    [
        ("a\\0b.pddl", r"task.problem: 'a\x00b.pddl': a path cannot hold a NUL byte"),
        ("a\\nb.pddl", r"a\nb.pddl: no such PDDL problem file"),
        ("x" * 5000, "task.problem: xxxx"),
    ],
    ids=["nul", "newline", "too-long"],
)
def test_a_path_no_file_system_holds_is_bad_input_on_one_line(tmp_path, value, words):
    path = tmp_path / "s.yaml"
    path.write_text(f'task: {{problem: "{value}"}}\n')
    r = _cli("cake_drake.run", "--scenario", str(path), "--out", str(tmp_path / "out"))
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and words in r.stderr, r.stderr
    assert len(r.stderr) < 300, r.stderr  # a long path is cut, not echoed whole
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "args",
    [
        ["cake_drake.plan", "models/pddl/blocksworld.pddl", "y" * 300],
        ["cake_drake.run", "--problem", "y" * 300, "--out", "o"],
        ["cake_drake.run", "--out", "y" * 300],
    ],
    ids=["plan-problem", "run-problem", "run-out"],
)
def test_a_name_too_long_at_any_door_is_bad_input(tmp_path, args):
    r = _cli(*args)
    assert r.returncode == 2, r.stderr
    assert r.stderr.startswith("error: yyyy") and r.stderr.count("\n") == 1, r.stderr


def test_skills_beside_a_whole_task_policy_are_refused_in_one_line(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text(
        "both:\n"
        "  reference: !Policy {checkpoint: package://cake_drake/policies/stack2}\n"
        "  motion: {skills: package://cake_drake/policies/skills_joint_space}\n"
    )
    r = _cli("cake_drake.run", "--scenario", str(path), "--name", "both",
             "--out", str(tmp_path / "out"))  # fmt: skip
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1
    said = "motion.skills (package://cake_drake/policies/skills_joint_space) with reference"
    assert said + ": !Policy" in r.stderr
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


def hanging_skill(path, device, ensemble=0.0):
    return _HangingSkill()


def _no_check(path, device, action_space=""):
    return None


def test_a_skill_that_hangs_is_stopped_at_its_budget_naming_it(monkeypatch, tmp_path):
    monkeypatch.setattr("cake_drake.scenario.SKILL_POLICY", f"{__name__}:hanging_skill")
    monkeypatch.setattr("cake_drake.pipeline.SKILL_CHECK", f"{__name__}:_no_check")
    monkeypatch.syspath_prepend(str(ROOT))
    s = Scenario()
    s.motion.skills = str(tmp_path)
    t0 = time.monotonic()
    with pytest.raises(PluginError) as e:
        run(s, write=False)
    assert time.monotonic() - t0 < 25
    assert e.value.exit_code == EXIT_EXECUTION_FAILED
    assert f"skill '{tmp_path.resolve()}'" in str(e.value) and "0.5 s" in str(e.value)


class _StandingSkill:
    """A skill that moves the hand and answers no move at all, its gripper open."""

    action_space = "ee_delta"

    def reset(self):
        pass

    def act(self, observation):
        return np.r_[np.zeros(6), 1.0]


def standing_skill(path, device, ensemble=0.0):
    return _StandingSkill()


def test_a_skill_whose_hand_stands_still_ends_its_try_there(monkeypatch, tmp_path):
    """A hand stood still with its action not done ends its try after ``STILL_END_S``, not at
    its budget: three tries of 2 s, not of 15, and the message and the summary say so."""
    from cake_drake.policy.shield import STILL_END_S
    from cake_drake.systems.skills import DEFAULT_BUDGET

    monkeypatch.setattr("cake_drake.scenario.SKILL_POLICY", f"{__name__}:standing_skill")
    monkeypatch.setattr("cake_drake.pipeline.SKILL_CHECK", f"{__name__}:_no_check")
    monkeypatch.syspath_prepend(str(ROOT))
    s = Scenario()
    s.motion.skills = str(tmp_path)
    s.outputs.render = False
    result = run(s, write=False)
    assert not result.success
    assert f"in 3 tries of {DEFAULT_BUDGET} steps each" in result.message, result.message
    assert f"; the last ended with the hand still for {STILL_END_S:g} s" in result.message
    skills = result.execution.monitoring["skills"]
    assert skills["stood_still"] == 3 and skills["budget_ran_out"] == 0
    assert skills["steps"] < 3 * (STILL_END_S * 10 + 2)  # three stalls (10 Hz), no budget
    assert result.execution.sim_s < 3 * DEFAULT_BUDGET / 10 / 2


def test_the_lerobot_env_offers_only_learning_tasks():
    from cake_drake.learning.envs.lerobot_env import CakeDrakeEnv

    with pytest.raises(ValueError) as e:
        CakeDrakeEnv(task="learned_tower5")
    offered = str(e.value).split("choose one of: ")[1].split(", ")
    assert offered == ["stack2", "stack2_scratch", "tower3", "tower5", "blocks3", "skills",
                       "skills_hand", "skills_hand_tall", "skills_relative", "skills_tall",
                       "towers8"]  # fmt: skip
    assert CakeDrakeEnv(task="tower3").task == "tower3"


@pytest.fixture(scope="module")
def logged_run(tmp_path_factory) -> Path:
    """A real run's folder with its logs.npz (the residual's input)."""
    out = tmp_path_factory.mktemp("logged")
    s = Scenario()
    s.outputs.folder, s.outputs.render, s.outputs.logs = str(out), False, True
    assert run(s).success
    return out


def _write_npz_claiming(path: Path, shape: tuple[int, ...]) -> None:
    """An .npz whose one member's npy header claims ``shape`` of float64, with no data."""
    import io
    import zipfile

    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, {"descr": "<f8", "fortran_order": False, "shape": shape}
    )
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("huge.npy", b"\x93NUMPY\x01\x00" + header.getvalue()[8:])


@pytest.mark.parametrize(
    "damage, words",
    [
        ("truncated", "logs.npz: not a readable .npz"),
        ("six joints", "array 'q' has shape (N6, 6); expected (N, 7)"),
        ("time stands still", "times in 't' must strictly increase"),
        ("huge extra array", "its arrays hold more than 256 MiB ('huge' has shape"),
        ("nan", "array 'v' holds NaN"),
    ],
)
def test_damaged_logs_are_one_line_and_no_residual_is_written(logged_run, tmp_path, damage,
                                                              words):  # fmt: skip
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    logs = dict(np.load(logged_run / "logs.npz"))
    n = len(logs["t"])
    if damage == "truncated":
        data = (logged_run / "logs.npz").read_bytes()
        (run_dir / "logs.npz").write_bytes(data[: len(data) // 2])
    else:
        if damage == "six joints":
            for k in ("q", "v", "a_d", "tau_applied"):
                logs[k] = logs[k][:, :6]
            words = words.replace("N6", str(n))
        elif damage == "time stands still":
            logs["t"] = np.zeros(n)
        elif damage == "nan":
            logs["v"][5, 2] = np.nan
        np.savez(run_dir / "logs.npz", **logs)
        if damage == "huge extra array":
            import zipfile

            extra = tmp_path / "extra.npz"
            _write_npz_claiming(extra, (40_000, 1_000))
            with zipfile.ZipFile(extra) as src, zipfile.ZipFile(run_dir / "logs.npz", "a") as z:
                z.writestr("huge.npy", src.read("huge.npy"))
    r = _cli("cake_drake.train", "--residual", str(run_dir), "--out", str(tmp_path / "res"))
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and words in r.stderr, r.stderr
    assert not (tmp_path / "res").exists()


def test_a_residual_whose_weights_are_not_numbers_is_one_line(tmp_path):
    import json

    folder = tmp_path / "res"
    folder.mkdir()
    shipped = ROOT / "models" / "residuals" / "cubes_0.5kg" / "residual.json"
    data = json.loads(shipped.read_text())
    data["weights"] = [["heavy"] * len(data["weights"][0])] * len(data["weights"])
    (folder / "residual.json").write_text(json.dumps(data))
    path = tmp_path / "s.yaml"
    path.write_text(f"bad:\n  controller: !ComputedTorque {{residual: {folder}}}\n")
    r = _cli("cake_drake.run", "--scenario", str(path), "--name", "bad", "--out",
             str(tmp_path / "out"))  # fmt: skip
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and "residual.json: weights must be 7 x" in r.stderr
    assert not (tmp_path / "out").exists()


def _damaged_checkpoint(tmp_path: Path, damage: str) -> Path:
    import json
    import shutil

    folder = tmp_path / "policy"
    shutil.copytree(ROOT / "models" / "policies" / "stack2", folder)
    cfg_path = folder / "config.json"
    cfg = json.loads(cfg_path.read_text())
    if damage == "config not a mapping":
        cfg = [cfg]
    elif damage == "feature without shape":
        del cfg["input_features"]["observation.state"]["shape"]
    elif damage == "chunk size its weights lack":
        cfg["chunk_size"] = 20
    elif damage == "truncated weights":
        weights = folder / "model.safetensors"
        weights.write_bytes(weights.read_bytes()[:5000])
    cfg_path.write_text(json.dumps(cfg))
    return folder


@pytest.mark.parametrize(
    "damage, words",
    [
        ("config not a mapping", "config.json: holds a list, not a mapping"),
        ("feature without shape", "input_features.observation.state has no shape"),
        ("chunk size its weights lack", "tensor net.6.weight has shape [80, 512], but "
                                        "config.json (its features, n_obs_steps 2, chunk_size 20)"),
        ("truncated weights", "model.safetensors: not a readable safetensors file"),
    ],
)  # fmt: skip
@pytest.mark.parametrize("command", ["run", "evaluate"])
def test_a_checkpoint_whose_files_disagree_is_one_line_before_anything_runs(
    tmp_path, damage, words, command
):
    folder = _damaged_checkpoint(tmp_path, damage)
    suite = ROOT / "models" / "scenarios" / "learning.yaml"
    if command == "run":
        path = tmp_path / "s.yaml"
        path.write_text(
            "bad:\n  task: {problem: package://cake_drake/pddl/stack2.pddl}\n"
            f"  reference: !Policy {{checkpoint: {folder}}}\n"
        )
        args = ("cake_drake.run", "--scenario", str(path), "--name", "bad")
    else:
        args = ("cake_drake.evaluate", str(folder), "--suite", str(suite), "--name", "stack2",
                "--episodes", "1")  # fmt: skip
    r = _cli(*args, "--out", str(tmp_path / "out"))
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and words in r.stderr, r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "folder, marker, kind",
    [
        ("policies/skills", "skill.json", "relative_skill"),
        ("policies/skills_rl", "skill_rl.json", "skill_rl"),
        ("policies/stack2_pixels_rl", "rl.json", "rl"),
        ("planners/blocks", "planner.json", "planner"),
    ],
)
@pytest.mark.parametrize("bad", [True, 1.0, "1"], ids=["true", "float", "string"])
def test_a_format_that_is_not_a_whole_number_is_refused(tmp_path, folder, marker, kind, bad):
    import json
    import shutil

    from cake_drake import artifacts
    from cake_drake.errors import InputError

    copy = tmp_path / "copy"
    shutil.copytree(ROOT / "models" / folder, copy)
    meta = json.loads((copy / marker).read_text())
    meta["format"] = bad
    (copy / marker).write_text(json.dumps(meta))
    with pytest.raises(InputError, match=f"{marker}: field 'format' is {bad!r}; this version"):
        needs = {"action_space": "joint_position"} if kind == "rl" else {}
        artifacts.check(copy, kind, role="the test", **needs)
