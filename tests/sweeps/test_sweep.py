"""Sweeps: sweep files checked up front, runs expanded, and real sweeps on the pool and Ray."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import time

import pytest

from cake_drake import MODELS_DIR
from cake_drake.cli import main
from cake_drake.errors import InputError
from cake_drake.pipeline import run
from cake_drake.scenario import JointPd, Scenario, load_scenario
from cake_drake.sweeps import LocalPool, RayCluster, Sweep, parse_sweep, read_table, run_sweep
from cake_drake.sweeps.spec import _node, apply
from cake_drake.sweeps.worker import TIMINGS
from tests.helpers import ROOT

SMOKE = MODELS_DIR / "sweeps" / "smoke.yaml"


# --- sweep files ------------------------------------------------------------------------


def _bad(tmp_path, capsys, text: str) -> str:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    assert main(["sweep", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1, err
    assert not (tmp_path / "out").exists()
    return err


def test_unknown_axis_is_one_line_naming_file_line_and_fields(tmp_path, capsys):
    err = _bad(tmp_path, capsys, "grid:\n  world.time_step: [0.01]\n  controller.kdd: [[5]]\n")
    assert "bad.yaml:3:" in err and "controller.kdd" in err
    assert "valid fields of controller (!ComputedTorque): kp, kd" in err


def test_empty_axis_is_one_line(tmp_path, capsys):
    err = _bad(tmp_path, capsys, "grid:\n  world.time_step: []\n")
    assert "bad.yaml:2:" in err and "world.time_step is empty" in err


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("grdi: {seed: [1]}\n", "unknown key 'grdi' in the sweep; valid keys: description"),
        ("grid:\n  world.time_step: [fast]\n", "world.time_step = 'fast' is not a finite number"),
        ("grid:\n  world.time_step: 0.01\n", "needs a list of values"),
        ("grid:\n  world.nope.x: [1]\n", "unknown field 'world.nope.x'; valid fields of world"),
        ("grid:\n  seed.x: [1]\n", "seed is a int, not a mapping"),
        ("grid:\n  outputs.folder: [a, b]\n", "outputs.folder is set by the sweep"),
        ("grid:\n  seed: [1, 2]\nseeds: 2\n", "seed is set by both seeds and an axis"),
        ("seeds: 0\n", "runs nothing"),
        ("cases: []\n", "cases is a non-empty list"),
        ("collect: [nothing]\n", "unknown collector 'nothing'; choose one of: logs"),
        ("scenario: {world: {time_stp: 1}}\n", "unknown key 'time_stp' in world"),
        ("base: no_such.yaml\n", "no such scenario file"),
    ],
)
def test_bad_sweep_files_are_refused_with_one_line(tmp_path, capsys, text, expected):
    assert expected in _bad(tmp_path, capsys, text)


def test_grid_cases_and_seeds_expand_in_order():
    sweep = parse_sweep(
        "cases:\n"
        "  - {task.planner: gbfs-ff}\n"
        "  - {task.planner: astar-lmcut, world.time_step: 0.005}\n"
        "grid:\n  controller.kd: [[20], [5]]\n  task.generate.blocks: [3, 4]\n"
        "seeds: [0, 7]\n"
    )
    runs = sweep.runs()
    assert len(runs) == 2 * 2 * 2 * 2
    assert sweep.columns == [
        "case",
        "task.planner",
        "world.time_step",
        "controller.kd",
        "task.generate.blocks",
        "seed",
    ]
    first, last = runs[0], runs[-1]
    assert first.params == {
        "case": "0",
        "task.planner": "gbfs-ff",
        "world.time_step": 0.01,  # the base's value where a case does not set it
        "controller.kd": 20.0,
        "task.generate.blocks": 3,
        "seed": 0,
    }
    assert last.scenario.task.planner == "astar-lmcut" and last.scenario.world.time_step == 0.005
    assert last.scenario.controller.kd == [5.0] and last.scenario.seed == 7
    assert last.scenario.task.generate.blocks == 4 and last.scenario.task.generate.seed == 0
    assert [r.params["seed"] for r in runs[:4]] == [0, 7, 0, 7]


def test_an_axis_through_a_config_keeps_the_rest_of_it():
    base = Scenario(controller=JointPd(kp=[50.0]))
    s = apply(base, "controller.kd", _node([5.0]))
    assert isinstance(s.controller, JointPd) and s.controller.kp == [50.0]
    assert s.controller.kd == [5.0]
    assert base.controller.kd != [5.0], "the base is not changed"


def test_a_whole_config_can_be_an_axis(tmp_path):
    sweep = parse_sweep(
        "grid:\n  controller: [!ComputedTorque {kd: [5]}, !JointPd {}]\n", str(tmp_path / "s")
    )
    runs = sweep.runs()
    assert [type(r.scenario.controller).__name__ for r in runs] == ["ComputedTorque", "JointPd"]
    assert [r.params["controller"] for r in runs] == ["!ComputedTorque", "!JointPd"]


def test_relative_paths_are_taken_from_the_sweep_file(tmp_path):
    problem = tmp_path / "p.pddl"
    problem.write_text((MODELS_DIR / "pddl" / "problem_5.pddl").read_text())
    (tmp_path / "s.yaml").write_text("grid:\n  task.problem: [p.pddl]\n")
    from cake_drake.sweeps import load_sweep

    (only,) = load_sweep(tmp_path / "s.yaml").runs()
    assert only.scenario.task.problem == str(problem.resolve())


def test_a_base_scenario_by_file_and_name():
    sweep = parse_sweep(
        "base: {file: ../scenarios/exercise.yaml, name: position}\n",
        folder=MODELS_DIR / "sweeps",
    )
    assert isinstance(sweep.base.controller, JointPd)


def test_every_shipped_sweep_file_loads():
    from cake_drake.sweeps import load_sweep

    files = sorted((MODELS_DIR / "sweeps").glob("*.yaml"))
    assert {f.stem for f in files} >= {"smoke", "kd", "suite"}
    for f in files:
        assert load_sweep(f).runs(), f
    assert len(load_sweep(SMOKE).runs()) <= 4
    suite = load_sweep(MODELS_DIR / "sweeps" / "suite.yaml").runs()
    assert len(suite) == 30
    assert {r.params["case"] for r in suite} == {"exercise", "ipc", "typed"}
    assert sorted({r.params["task.generate.blocks"] for r in suite}) == list(range(3, 13))
    ipc = next(r for r in suite if r.params["case"] == "ipc")
    assert ipc.scenario.task.domain.endswith("variants/blocksworld-ipc.pddl")


def test_workers_and_ray_are_one_choice(capsys):
    assert main(["sweep", str(SMOKE), "--workers", "2", "--ray"]) == 2
    assert "not allowed with argument" in capsys.readouterr().err
    assert main(["sweep", str(SMOKE), "--workers", "0"]) == 2
    assert "--workers 0" in capsys.readouterr().err


def test_a_ray_address_nothing_answers_at_is_one_line_and_writes_nothing(tmp_path, capsys):
    pytest.importorskip("ray")
    out = tmp_path / "out"
    assert main(["sweep", str(SMOKE), "--ray", "127.0.0.1:1", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no Ray cluster answers there" in err
    assert not out.exists()


# --- real sweeps ------------------------------------------------------------------------


def _without_timings(rows: list[dict]) -> list[dict]:
    return [{k: v for k, v in r.items() if k not in TIMINGS} for r in rows]


@pytest.fixture(scope="module")
def smoke_pool(tmp_path_factory):
    out = tmp_path_factory.mktemp("smoke_pool")
    from cake_drake.sweeps import load_sweep

    result = run_sweep(load_sweep(SMOKE), out, LocalPool(2), progress=False)
    return out, result


@pytest.mark.slow
def test_smoke_on_the_pool_writes_table_plots_and_runs(smoke_pool):
    out, result = smoke_pool
    rows = read_table(out / "results.parquet")
    assert len(rows) == result.total == 4 and not result.interrupted
    assert [r["status"] for r in rows] == ["done"] * 4
    assert all(r["success"] for r in rows), [r["message"] for r in rows]
    assert {r["controller.kd"] for r in rows} == {20.0, 5.0}
    assert all(r["n_blocks"] == 3 and r["plan_length"] > 0 for r in rows)
    assert all(0 < r["ik_s"] < r["simulation_wall_s"] and r["ik_solves"] > 0 for r in rows)
    # A lower Kd tracks worse, on each problem.
    for seed in (1, 2):
        by_kd = {r["controller.kd"]: r for r in rows if r["task.generate.seed"] == seed}
        assert by_kd[5.0]["tracking_rms_mrad"] > by_kd[20.0]["tracking_rms_mrad"]
    csv_lines = (out / "results.csv").read_text().splitlines()
    assert len(csv_lines) == 5 and csv_lines[0].startswith("run_id,index,task.generate.seed")
    assert (out / "plots" / "controller.kd.png").stat().st_size > 10_000
    folder = out / rows[0]["folder"]
    assert {"scenario.yaml", "problem.pddl", "plan.txt", "summary.json", "row.json"} <= {
        p.name for p in folder.iterdir()
    }


@pytest.mark.slow
def test_a_row_reruns_alone_from_its_scenario(smoke_pool):
    out, _ = smoke_pool
    row = read_table(out / "results.parquet")[3]
    scenario = load_scenario(out / row["folder"] / "scenario.yaml")
    again = run(scenario, write=False)
    assert again.success == row["success"]
    assert len(again.plan.actions) == row["plan_length"]
    assert round(again.execution.sim_s, 4) == row["sim_s"]
    plan = (out / row["folder"] / "plan.txt").read_text().splitlines()
    assert [str(a) for a in again.plan.actions] == plan[: row["plan_length"]]


@pytest.mark.slow
def test_smoke_on_local_ray_gives_the_same_table(smoke_pool, tmp_path):
    pytest.importorskip("ray")
    out, _ = smoke_pool
    result = run_sweep(
        parse_sweep(SMOKE.read_text(), str(SMOKE), SMOKE.parent),
        tmp_path,
        RayCluster(num_cpus=2),
        progress=False,
    )
    assert result.total == 4 and not result.interrupted
    ray_rows = read_table(tmp_path / "results.parquet")
    pool_rows = read_table(out / "results.parquet")
    assert _without_timings(ray_rows) == _without_timings(pool_rows)
    assert {r["worker"] for r in ray_rows} != {r["worker"] for r in pool_rows}


PLUGINS = """
import os


def explode(problem, time_limit):
    raise ZeroDivisionError("a planner that divides by zero")


def die(problem, time_limit):
    os._exit(7)
"""


@pytest.mark.slow
def test_a_raising_and_a_dying_run_are_rows_and_the_sweep_finishes(tmp_path, monkeypatch):
    (tmp_path / "sweep_plugins.py").write_text(PLUGINS)
    monkeypatch.syspath_prepend(str(tmp_path))  # spawned workers inherit sys.path
    scratch = tmp_path / "tmp"  # the temporary folder of this process and its workers
    scratch.mkdir()
    monkeypatch.setenv("TMPDIR", str(scratch))
    monkeypatch.setattr(tempfile, "tempdir", None)  # read TMPDIR again
    base = Scenario()
    base.task.generate = load_scenario_generate(3, 2)
    base.outputs.render = False
    sweep = Sweep.of(
        base,
        cases=[
            {"task.planner": "sweep_plugins:explode"},
            {"task.planner": "sweep_plugins:die"},
            {"task.planner": "auto"},
        ],
    )
    result = run_sweep(sweep, tmp_path / "out", LocalPool(2), progress=False)
    rows = read_table(tmp_path / "out" / "results.parquet")
    assert [r["task.planner"] for r in rows] == [
        "sweep_plugins:explode",
        "sweep_plugins:die",
        "auto",
    ]
    explode, die, ok = rows
    assert explode["status"] == "failed" and not explode["success"]
    assert explode["error"].startswith(
        "planner 'sweep_plugins:explode' raised ZeroDivisionError: a planner that divides by zero"
    ) and explode["error"].endswith("sweep_plugins.py:6")
    assert die["status"] == "crashed" and "worker process died" in die["error"]
    assert ok["status"] == "done" and ok["success"], ok["message"]
    assert result.count("done") == 1
    # The dead worker could not remove its scratch folder; the sweep removed it.
    assert list(scratch.iterdir()) == []
    # Even a failed run keeps its scenario, to be re-run alone.
    assert (tmp_path / "out" / explode["folder"] / "scenario.yaml").is_file()


def load_scenario_generate(blocks: int, seed: int):
    from cake_drake.scenario import Generate

    return Generate(blocks=blocks, seed=seed)


@pytest.mark.slow
def test_ctrl_c_keeps_what_finished_and_resume_runs_only_the_rest(tmp_path):
    out = tmp_path / "out"
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
    }
    cmd = [sys.executable, "-m", "cake_drake.sweep", str(SMOKE), "--out", str(out)]
    proc = subprocess.Popen(
        [*cmd, "--workers", "1"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    deadline = time.monotonic() + 300
    while not list(out.glob("runs/*/row.json")):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "no run finished"
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr
    assert "interrupted" in stderr.splitlines()[-1]
    kept = read_table(out / "results.parquet")
    assert 1 <= len(kept) < 4, "the sweep stopped early and kept what finished"
    before = {
        p.parent.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in out.glob("runs/*/row.json")
    }
    assert set(before) == {r["run_id"] for r in kept}

    again = subprocess.run([*cmd, "--quiet"], env=env, capture_output=True, text=True)
    assert again.returncode == 2 and "--resume" in again.stderr  # a full folder is not reused

    resumed = subprocess.run([*cmd, "--resume", "--quiet"], env=env, capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    assert f"({len(kept)} kept from before)" in resumed.stdout
    rows = read_table(out / "results.parquet")
    assert len(rows) == 4 and all(r["status"] == "done" for r in rows)
    for run_id, (data, mtime) in before.items():
        p = out / "runs" / run_id / "row.json"
        assert p.read_bytes() == data and p.stat().st_mtime_ns == mtime, f"{run_id} ran again"
    assert json.loads((out / "runs" / rows[-1]["run_id"] / "row.json").read_text())["index"] == 3


def test_input_error_for_a_sweep_of_nothing_to_vary_is_not_raised():
    # A sweep with no axes is one run of its base: allowed.
    assert len(parse_sweep("description: one run\n").runs()) == 1
    with pytest.raises(InputError, match="a sweep file is a mapping"):
        parse_sweep("- 1\n")


def test_a_categorical_axis_is_drawn_as_categories_in_file_order():
    from cake_drake.sweeps.table import axis_figure

    rows = [
        {"task.planner": p, "status": "done", "success": True, "tracking_rms_mrad": 1.0,
         "plan_length": n, "wall_s": 1.0}
        for p, n in [("gbfs-ff", 14), ("astar-lmcut", 10), ("wastar-ff", 12)]
    ]  # fmt: skip
    fig = axis_figure(rows, "task.planner")
    ax = fig.axes[2]  # plan length
    assert [t.get_text() for t in ax.get_xticklabels()] == ["gbfs-ff", "astar-lmcut", "wastar-ff"]
    (line,) = ax.get_lines()
    assert line.get_linewidth() == 0 and list(line.get_ydata()) == [14, 10, 12]
