"""Scenarios: typed YAML in and out, errors with file and line, plug-ins refused up front."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest

from cake_drake.errors import InputError
from cake_drake.pipeline import check
from cake_drake.scenario import (
    ComputedTorque,
    CustomController,
    JointPd,
    Recorded,
    Scenario,
    dump_scenario,
    load_scenario,
    parse_scenario,
    scenario_names,
)
from tests.helpers import ROOT

SCENARIOS = ROOT / "models" / "scenarios"


def test_dump_and_parse_give_back_the_same_scenario():
    s = Scenario(controller=JointPd(kp=[1.0] * 7), reference=Recorded("/x.npz", "central"))
    s.world.time_step = 0.005
    s.motion.timing.gentle_phases = ["place"]
    s.task.time_limit = 2.5
    s.seed = 7
    assert parse_scenario(dump_scenario(s)) == s


def test_every_field_is_written_with_the_package_versions():
    text = dump_scenario(Scenario())
    for key in (
        "task:",
        "world:",
        "motion:",
        "controller:",
        "reference:",
        "simulation:",
        "outputs:",
        "visualization:",
        "seed:",
        "time_step:",
        "velocity_fraction:",
    ):
        assert key in text, key
    assert "drake 1." in text and "cake_drake" in text


def test_package_versions_agree_with_the_installed_metadata():
    from importlib.metadata import version

    from cake_drake.scenario import package_versions

    found = package_versions()
    for name in ("drake", "numpy", "pyperplan", "matplotlib"):
        assert found[name] == version(name), name


@pytest.mark.parametrize(
    "text, words",
    [
        ("world:\n  time_stp: 0.01\n", ["x.yaml:2", "'time_stp'", "valid keys: time_step"]),
        ("controller: !Lqr {}\n", ["x.yaml:1", "!Lqr", "!ComputedTorque, !JointPd, !Pid"]),
        ("seed: 1\nworld:\n  time_step: fast\n", ["x.yaml:3", "world.time_step", "finite"]),
        ("world: {time_step: .nan}\n", ["x.yaml:1", "finite"]),
        ("task: [1, 2]\n", ["x.yaml:1", "task must be a mapping"]),
        ("seed: 1\nseed: 2\n", ["x.yaml:2", "twice"]),
        ("world: {time_step: [1}\n", ["x.yaml:1", "not valid YAML"]),
        ("controller: !ComputedTorque {kp: 100}\n", ["x.yaml:1", "controller.kp must be a list"]),
        ("a: {seed: 1}\nb: {seed: 2}\n", ["holds the scenarios a, b", "--name"]),
    ],
)
def test_bad_scenario_text_names_the_file_and_line(text, words):
    with pytest.raises(InputError) as e:
        parse_scenario(text, "x.yaml")
    message = str(e.value)
    assert "\n" not in message
    for w in words:
        assert w in message, message


def test_a_named_scenario_is_chosen_and_a_missing_name_is_listed():
    text = "slow: {world: {time_step: 0.005}}\nfast: {world: {time_step: 0.02}}\n"
    assert parse_scenario(text, "x.yaml", "fast").world.time_step == 0.02
    with pytest.raises(InputError, match="no scenario named 'medium'; it holds slow, fast"):
        parse_scenario(text, "x.yaml", "medium")


def test_relative_paths_are_taken_from_the_scenario_file(tmp_path):
    (tmp_path / "p.pddl").write_text("")
    f = tmp_path / "s.yaml"
    f.write_text("task: {problem: p.pddl}\nreference: !Recorded {path: ../t.npz}\n")
    s = load_scenario(f)
    assert s.task.problem == str(tmp_path / "p.pddl")
    assert s.reference.path == str(tmp_path.parent / "t.npz")
    assert s.task.domain == "package://cake_drake/pddl/blocksworld.pddl"


@pytest.mark.parametrize(
    "planner, expected",
    [
        ("learned@pl", "learned@{tmp}/pl"),
        ("learned@../pl", "learned@{parent}/pl"),
        ("learned@package://cake_drake/planners/blocks", "learned@package://cake_drake/planners/blocks"),
        ("learned@{root}/models/planners/blocks", "learned@package://cake_drake/planners/blocks"),
        ("learned", "learned"),
        ("astar-lmcut", "astar-lmcut"),
        ("examples.pid_controller:make", "examples.pid_controller:make"),
    ],
)  # fmt: skip
def test_a_learned_planners_folder_is_a_scenario_path(tmp_path, planner, expected):
    # learned@DIR names a folder: like every path of a scenario, taken from the file's
    # folder and saved absolute (or as a package URL); other planner names are names.
    f = tmp_path / "s.yaml"
    f.write_text(f"task: {{planner: '{planner.format(root=ROOT)}'}}\n")
    got = load_scenario(f).task.planner
    assert got == expected.format(tmp=tmp_path.resolve(), parent=tmp_path.resolve().parent)


@pytest.mark.slow
def test_a_scenario_with_learned_at_a_folder_beside_it_runs_from_any_working_folder(tmp_path):
    shutil.copytree(ROOT / "models" / "planners" / "blocks", tmp_path / "pl")
    f = tmp_path / "s.yaml"
    f.write_text("task: {planner: learned@pl, problem: package://cake_drake/pddl/stack2.pddl}\n")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    out = tmp_path / "out"
    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.run", "--scenario", str(f), "--out", str(out),
         "--quiet", "--no-render"],
        capture_output=True, text=True, cwd=elsewhere, timeout=600,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    # The saved scenario names the folder absolute: it runs again from anywhere.
    saved = load_scenario(out / "scenario.yaml")
    assert saved.task.planner == f"learned@{(tmp_path / 'pl').resolve()}"
    assert f"planner: learned@{(tmp_path / 'pl').resolve()}" in (out / "scenario.yaml").read_text()


@pytest.mark.parametrize("path", sorted(SCENARIOS.glob("*.yaml")), ids=lambda p: p.stem)
def test_every_shipped_scenario_loads(path):
    names = scenario_names(path)
    assert names, f"{path.name} should hold named scenarios"
    for name in names:
        load_scenario(path, name)


@pytest.mark.parametrize(
    "change, words",
    [
        (lambda s: setattr(s.task, "planner", "nope"), "unknown planner 'nope'"),
        (lambda s: setattr(s.task, "planner", "no_such_module:plan"), "cannot import module"),
        (lambda s: setattr(s.task, "planner", "math:no_such"), "has no attribute 'no_such'"),
        (lambda s: setattr(s.motion, "ik", "math:pi"), "is not callable"),
        (lambda s: setattr(s.reference, "action_source", "x"), "unknown action source 'x'"),
        (lambda s: setattr(s, "controller", CustomController("math:sqrt")), "does not take"),
        (lambda s: setattr(s, "controller", CustomController("math:hypot")), "without name"),
        (lambda s: setattr(s, "controller", ComputedTorque(kd=[float("nan")])), "finite"),
        (lambda s: setattr(s, "controller", JointPd(kp=[1.0, 2.0])), "one value or seven"),
        (lambda s: setattr(s.simulation, "max_sim_s", 1e9), "simulation.max_sim_s"),
        (lambda s: setattr(s.motion.timing, "velocity_fraction", 0.0), "velocity_fraction"),
        (lambda s: setattr(s.task, "problem", "/no/such.pddl"), "no such"),
        (lambda s: setattr(s, "reference", Recorded("")), "needs a path"),
    ],
)
def test_check_refuses_bad_scenarios_before_anything_is_built(change, words):
    s = Scenario()
    change(s)
    with pytest.raises(InputError) as e:
        check(s, write=False)
    assert words in str(e.value), str(e.value)


def test_an_output_folder_that_is_a_file_is_refused_up_front(tmp_path):
    s = Scenario()
    (tmp_path / "f").write_text("x")
    s.outputs.folder = str(tmp_path / "f")
    with pytest.raises(InputError, match="is not a folder"):
        check(s)


def test_cli_flags_override_the_scenario_file(tmp_path):
    from cake_drake.commands.run import run_parser, scenario_from_args

    f = tmp_path / "s.yaml"
    f.write_text("k: {controller: !ComputedTorque {kp: [50.0], kd: [5.0]}, seed: 3}\n")
    args = run_parser().parse_args(
        ["--scenario", str(f), "--name", "k", "--kd", "7", "--seed", "4"]
    )
    s = scenario_from_args(args)
    assert s.controller == ComputedTorque(kp=[50.0], kd=[7.0]) and s.seed == 4
    args = run_parser().parse_args(["--scenario", str(f), "--name", "k", "--mode", "position"])
    assert isinstance(scenario_from_args(args).controller, JointPd)


@pytest.mark.slow
def test_a_run_is_reproduced_bit_for_bit_from_its_scenario_yaml(tmp_path):
    def cli(*args):
        r = subprocess.run(
            [sys.executable, "-m", "cake_drake.run", "--quiet", "--no-render", *args],
            capture_output=True,
            text=True,
            cwd=ROOT,
        )
        assert r.returncode == 0, r.stderr
        return r

    first, second = tmp_path / "first", tmp_path / "second"
    cli("--mode", "position", "--seed", "3", "--time-step", "0.008", "--out", str(first))
    cli("--scenario", str(first / "scenario.yaml"), "--out", str(second))
    a, b = np.load(first / "trajectory.npz"), np.load(second / "trajectory.npz")
    assert sorted(a.files) == sorted(b.files)
    for key in a.files:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    plan = [line for line in (first / "plan.txt").read_text().splitlines() if "time" not in line]
    again = [line for line in (second / "plan.txt").read_text().splitlines() if "time" not in line]
    assert plan == again
    saved = load_scenario(second / "scenario.yaml")
    assert saved == load_scenario(first / "scenario.yaml").__class__(
        **{**load_scenario(first / "scenario.yaml").__dict__, "outputs": saved.outputs}
    )
    assert saved.seed == 3 and saved.world.time_step == 0.008


# --- --set: any field from the command line ------------------------------------------------


def test_a_setting_is_read_as_yaml_and_written_over_the_scenario():
    from cake_drake.scenario import Pid, with_settings

    s = with_settings(Scenario(), [
        "perception.noise.model=axial", "world.cube_mass_kg=0.5", "controller=!Pid {kp: [50]}",
        "perception.cameras=[{name: top, xyz: [0.5, 0, 1.2]}]", "seed=7",
        "task.problem=models/pddl/tower3.pddl",  # from the working folder
    ])  # fmt: skip
    assert s.perception.noise.model == "axial" and s.perception.noise.sigma_m == 0.0012
    assert s.world.cube_mass_kg == 0.5 and s.seed == 7
    assert isinstance(s.controller, Pid) and s.controller.kp == [50.0]
    assert [c.name for c in s.perception.cameras] == ["top"]
    assert s.task.problem == "package://cake_drake/pddl/tower3.pddl"
    assert s.task.planner == Scenario().task.planner  # the rest as it was
    s = with_settings(Scenario(), ["task.generate={blocks: 8, tall: true}", 'task.problem=""'])
    assert s.task.generate.blocks == 8 and s.task.generate.tall and s.task.problem == ""


@pytest.mark.parametrize(
    ("given", "words"),
    [
        (
            "perception.noise.modle=axial",
            "--set perception.noise.modle: unknown key 'modle' in perception.noise; valid keys: "
            "model, sigma_m, growth",
        ),
        ("world.cube_mass_kg=heavy", "--set world.cube_mass_kg: world.cube_mass_kg = 'heavy'"),
        ("perception", "--set 'perception': give section.field=VALUE"),
        ("percepton.estimator=depth", "unknown key 'percepton' in the scenario; valid keys: task"),
    ],
)
def test_a_bad_setting_is_one_line_naming_the_field(given, words):
    from cake_drake.scenario import with_settings

    with pytest.raises(InputError, match=re.escape(words)):
        with_settings(Scenario(), [given])


LEARNING = "models/scenarios/learning.yaml"


@pytest.mark.parametrize(
    "command",
    [
        ["run"],
        ["run", "--scenario", "models/scenarios/exercise.yaml", "--name", "pid"],
        ["evaluate", "package://cake_drake/policies/stack2", "--suite", LEARNING, "--name",
         "stack2"],
        ["record", LEARNING, "--name", "stack2", "--out", "{tmp}/d"],
        ["sweep", "models/sweeps/smoke.yaml", "--out", "{tmp}/s"],
        ["train", "--rl", LEARNING, "--name", "stack2", "--out", "{tmp}/t"],
        ["gains", "--out", "{tmp}/g"],
    ],
    ids=lambda c: "-".join(c[:2]) if c[:2] == ["run", "--scenario"] else c[0],
)  # fmt: skip
def test_every_command_that_reads_a_scenario_takes_set(tmp_path, command):
    args = [a.replace("{tmp}", str(tmp_path)) for a in command]
    r = subprocess.run(
        [sys.executable, "-m", f"cake_drake.{args[0]}", *args[1:], "--set", "world.cube_mas_kg=1"],
        capture_output=True, text=True, cwd=ROOT, timeout=300,
    )  # fmt: skip
    assert r.returncode == 2, r.stdout + r.stderr
    assert (
        r.stderr.startswith(
            "error: --set world.cube_mas_kg: unknown key 'cube_mas_kg' in world; valid keys: "
        )
        and r.stderr.count("\n") == 1
    ), r.stderr
    assert not list(tmp_path.iterdir())


@pytest.mark.slow
def test_a_run_with_settings_records_them_in_its_scenario(tmp_path):
    """Fields no flag sets, set from the command line; scenario.yaml runs it again."""
    out = tmp_path / "o"
    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.run", "--set", "world.cube_mass_kg=0.06", "--set",
         "perception.estimator=depth", "--quiet", "--out", str(out)],
        capture_output=True, text=True, cwd=ROOT, timeout=600,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    again = load_scenario(out / "scenario.yaml")
    assert again.world.cube_mass_kg == 0.06 and again.perception.estimator == "depth"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["perception"]["estimator"] == "depth"
