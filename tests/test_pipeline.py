"""End-to-end: the whole cake on the simulated Panda, verdicts measured from poses."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time

import numpy as np
import pytest

from cake_drake.formats import load_npz
from cake_drake.pipeline import run
from cake_drake.symbolic import random_problem
from tests.helpers import DATA, ROOT, scenario

pytestmark = pytest.mark.slow
OUTPUTS = {"plan.txt", "trajectory.npz", "final_state.png", "joint4_torque.png", "summary.json"}


def cli(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "cake_drake.run", "--quiet", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
    )


def assert_tower(summary: dict, goal_on: list[tuple[str, str]]) -> None:
    """Check the stacking independently of the run's own verdict, from the saved poses."""
    blocks = {k: np.array(v["position"]) for k, v in summary["blocks"].items()}
    for top, below in goal_on:
        dz = blocks[top][2] - blocks[below][2]
        dxy = np.linalg.norm(blocks[top][:2] - blocks[below][:2])
        assert abs(dz - 0.04) < 0.004, f"{top} is {dz * 1000:.1f} mm above {below}"
        assert dxy < 0.005, f"{top} stands {dxy * 1000:.1f} mm off {below}"


def test_torque_mode_builds_the_tower_and_writes_every_output(tmp_path):
    r = cli("--mode", "torque", "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    assert "goal reached: a on b on c on d on e" in r.stdout
    assert OUTPUTS <= {p.name for p in tmp_path.iterdir()}
    assert not any(p.name.startswith(".staging") for p in tmp_path.iterdir())
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["success"] is True and summary["mode"] == "torque"
    assert len(summary["plan"]) == 10
    assert_tower(summary, [("a", "b"), ("b", "c"), ("c", "d"), ("d", "e")])
    assert abs(summary["blocks"]["e"]["position"][2] - 0.02) < 0.002  # e on the table
    assert "(on a b)" in summary["facts"] and "(on-table e)" in summary["facts"]
    plan = (tmp_path / "plan.txt").read_text()
    assert plan.startswith("(unstack a b)") and "; cost = 10 (unit cost)" in plan
    traj = load_npz(tmp_path / "trajectory.npz")
    assert traj["q"].shape[1] == 7 and len(traj["actions"]) == 10
    assert set(np.unique(traj["phase"])) >= {1, 2, 3, 4, 5, 6}


def test_replay_of_a_saved_trajectory_in_torque_mode(position_run, tmp_path):
    out, _ = position_run
    r = cli(
        "--mode",
        "torque",
        "--reference",
        str(out / "trajectory.npz"),
        "--differentiate",
        "central",
        "--out",
        str(tmp_path),
        "--no-render",
    )
    assert r.returncode == 0, r.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["reference"].endswith("trajectory.npz")
    assert_tower(summary, [("a", "b"), ("b", "c"), ("c", "d"), ("d", "e")])


@pytest.mark.parametrize("mode", ["position", "torque"])
def test_a_generated_three_block_problem(mode, tmp_path):
    problem = tmp_path / "p3.pddl"
    problem.write_text(random_problem(3, seed=4))
    result = run(scenario(mode, problem), write=False)
    assert result.success, result.message
    from cake_drake.symbolic import BLOCKSWORLD_DOMAIN, load_problem

    goal = load_problem(BLOCKSWORLD_DOMAIN, problem).goal
    assert goal <= result.execution.reading.facts


def test_same_inputs_same_plan_and_trajectory():
    a = run(scenario("torque"), write=False)
    b = run(scenario("torque"), write=False)
    assert a.plan.actions == b.plan.actions
    np.testing.assert_array_equal(a.execution.logs.q_d, b.execution.logs.q_d)
    np.testing.assert_array_equal(a.execution.logs.q, b.execution.logs.q)


def test_unreachable_cube_is_exit_3_naming_the_action(tmp_path):
    # 0.9 m: on the table, out of reach. Open loop, IK fails at the first action; the
    # monitor sees it in the world before the arm moves.
    r = cli("--slot-radius", "0.9", "--out", str(tmp_path / "a"), "--no-render", "--no-monitor")
    assert r.returncode == 3
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
    assert "action 1 (unstack a b)" in r.stderr and "pre-grasp" in r.stderr
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert summary["success"] is False and "unstack a b" in summary["error"]
    r = cli("--slot-radius", "0.9", "--out", str(tmp_path / "b"), "--no-render")
    assert r.returncode == 3 and r.stderr.count("\n") == 1
    assert "cannot be recovered" in r.stderr and "out of the arm's reach" in r.stderr


@pytest.mark.parametrize(
    "args, code, words",
    [
        (["--problem", "/no/such.pddl"], 2, "no such"),
        (["--planner", "nope"], 2, "nope"),
        (["--kp", "1", "2", "3"], 2, "one value or seven"),
        (["--ik", "trac"], 2, "drake"),
        (["--avoid-collisions", "--no-collision-check"], 2, "collision_check"),
        (["--kd", "nan"], 2, "finite"),
        (["--kp", "inf"], 2, "finite"),
        (["--differentiate", "central"], 2, "--reference"),
        (["--name", "x"], 2, "--scenario"),
    ],
)
def test_bad_input_is_one_line_and_writes_nothing(tmp_path, args, code, words):
    out = tmp_path / "out"
    r = cli(*args, "--out", str(out), cwd=tmp_path)
    assert r.returncode == code, r.stderr
    assert r.stderr.startswith("error: ") and r.stderr.count("\n") == 1, r.stderr
    assert words in r.stderr
    assert not out.exists() or not any(out.iterdir())


def test_bad_reference_file_is_one_line(tmp_path):
    bad = tmp_path / "t.npz"
    np.savez(bad, t=np.arange(5.0), q=np.zeros((5, 6)), gripper=np.zeros(5))
    r = cli("--reference", str(bad), "--out", str(tmp_path / "o"))
    assert r.returncode == 2 and "expected (N, 7)" in r.stderr
    assert r.stderr.count("\n") == 1


def test_invalid_plan_file_is_exit_1(tmp_path):
    plan = tmp_path / "plan.txt"
    plan.write_text("(unstack a b)\n(stack a c)\n")
    r = cli("--plan", str(plan), "--out", str(tmp_path / "o"))
    assert r.returncode == 1
    assert "step 2" in r.stderr and r.stderr.count("\n") == 1


def test_collisions_are_reported_and_avoided_on_a_crowded_table(tmp_path):
    # Slots 0.4 m from the base stand 10 cm apart: the 20 cm-wide hand reaching for c
    # sweeps through the d-e tower. The plan is fine symbolically; geometry is not.
    crowd = ("--slot-radius", "0.4", "--slot-spacing", "0.104")
    crowded = cli(*crowd, "--out", str(tmp_path / "a"), "--no-render", "--no-monitor")
    assert crowded.returncode == 3
    lines = crowded.stderr.strip().splitlines()
    # The hand sweeping through a neighbouring tower is reported, naming the action,
    # the phase and the cube (which action first depends on how the towers stand).
    hits = re.compile(r"warning: collision: action \d+ \(.+\), [a-z-]+: panda_hand hits cube \w")
    assert any(hits.match(line) for line in lines), crowded.stderr
    assert lines[-1].startswith("error: plan not executed")
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert summary["collisions"] and summary["success"] is False
    avoided = cli(*crowd, "--avoid-collisions", "--out", str(tmp_path / "b"), "--no-render")
    assert avoided.returncode == 0, avoided.stderr
    assert "goal reached" in avoided.stdout


@pytest.mark.parametrize("module", ["run", "gains", "sweep", "world", "plan", "validate", "saycan"])
def test_every_cli_reports_a_bad_command_line_in_one_line(module):
    r = subprocess.run(
        [sys.executable, "-m", f"cake_drake.{module}", "--no-such-flag"],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2
    assert r.stderr.startswith("error: ") and r.stderr.count("\n") == 1, r.stderr


VARIANTS = ROOT / "models" / "pddl" / "variants"


@pytest.mark.parametrize(
    "domain, problem, tower",
    [
        ("blocksworld-ipc.pddl", "ipc_blocks_4_0.pddl", "d on c on b on a"),
        ("blocksworld-typed.pddl", "typed_5.pddl", "a on b on c on d on e"),
        ("blocksworld-renamed.pddl", "renamed_5.pddl", "a on b on c on d on e"),
    ],
)
def test_every_blocksworld_naming_runs_end_to_end(domain, problem, tower, tmp_path):
    r = cli(
        "--domain", str(VARIANTS / domain), "--problem", str(DATA / problem),
        "--out", str(tmp_path), "--no-render",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert f"goal reached: {tower}" in r.stdout
    plan = (tmp_path / "plan.txt").read_text()
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["success"] is True
    if "ipc" in domain:
        assert "(pickup" in plan or "(unstack" in plan


@pytest.mark.parametrize(
    "domain, problem_text, words",
    [
        ("kitchen", None, "not a Blocksworld domain the robot can execute"),
        (None, "(on-table a) (on-table b) (holding c) (clear a) (clear b)", "in the hand"),
        (None, "(on-table a) (on b a) (on c a) (clear b) (clear c) (arm-empty)", "a has 2 blocks"),
    ],
)
def test_what_the_world_cannot_run_is_refused_before_simulating(
    tmp_path, domain, problem_text, words
):
    from cake_drake.symbolic import BLOCKSWORLD_DOMAIN, MODELS_DIR

    args = []
    if domain == "kitchen":
        args = ["--domain", str(MODELS_DIR / "pddl" / "kitchen.pddl"),
                "--problem", str(MODELS_DIR / "pddl" / "kitchen_snack.pddl")]  # fmt: skip
    else:
        p = tmp_path / "p.pddl"
        p.write_text(
            "(define (problem p) (:domain blocksworld) (:objects a b c)\n"
            f"  (:init {problem_text}) (:goal (and (on a b))))\n"
        )
        args = ["--domain", str(BLOCKSWORLD_DOMAIN), "--problem", str(p)]
    r = cli(*args, "--out", str(tmp_path / "o"))
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and words in r.stderr, r.stderr
    assert "simulat" not in r.stderr and not (tmp_path / "o").exists()


def test_the_progress_bar_keeps_its_width_when_a_recovery_runs_past_the_plan(capsys):
    from cake_drake.execution import ProgressBar

    bar = ProgressBar(10, lambda k: f"(step {k})")
    bar.update(5.0, 1.0, 13)
    bar.update(9.0, 2.0, 14, final=True)
    lines = capsys.readouterr().err.splitlines()
    assert [ln[ln.index("[") : ln.index("]") + 1] for ln in lines] == ["[" + "#" * 20 + "]"] * 2
    assert "action 14 of 10+ (recovering)" in lines[0] and "action 10/10 done" in lines[1]


def test_the_progress_line_counts_a_policys_steps_and_a_skills_action(capsys):
    from cake_drake.execution import ProgressBar

    policy = ProgressBar(400, lambda k: "", unit="step")
    policy.update(3.2, 1.0, 32)
    policy.update(4.0, 3.0, 40, final=True)
    skills = ProgressBar(10, lambda k: f"(plan action {k})")
    skills.update(20.0, 1.0, 3, note="(unstack b c), skill step 12/150")
    skills.update(40.0, 3.0, 12, note="(stack a b), skill step 5/150")
    lines = capsys.readouterr().err.splitlines()
    assert "policy step 32/400" in lines[0] and "recovering" not in lines[0]
    assert lines[1].endswith("policy step 40/400 done")
    assert lines[2].endswith("action 4/10 (unstack b c), skill step 12/150")
    assert lines[3].endswith("action 13 of 10+ (stack a b), skill step 5/150")


def test_the_joint_plot_marks_each_fault_when_it_struck():
    from types import SimpleNamespace

    from cake_drake.outputs.report import fault_marks
    from cake_drake.world.faults import Knock, Move, Slip

    logs = SimpleNamespace(t=np.arange(0, 5, 0.5), action=np.array([-1, 0, 0, 1, 1, 2, 2, 2, 3, 3]))
    marks = fault_marks([Knock(cube="c", time=1.2), Move(cube="a", time=3.0), Slip(action=3)], logs)
    assert marks == [(1.2, "knock c"), (3.0, "move a"), (2.5, "slip (action 3)")]


@pytest.mark.alone
def test_helpers_or_not_the_outputs_are_the_same_bytes(tmp_path):
    """The picture and the plot drawn in helper processes (with the plot's figure
    prepared ahead, see outputs.plots.joint_figure) or in the run's own process: the same
    files, byte for byte (the timings in the summary and the plan aside)."""
    written = {}
    for helpers in ("always", "never"):
        s = scenario("position", folder=str(tmp_path / helpers), helpers=helpers)
        result = run(s)
        assert result.success, result.message
        written[helpers] = tmp_path / helpers
    always, never = written["always"], written["never"]
    for name in ("final_state.png", "joint4_torque.png", "cake.png", "trajectory.npz"):
        assert (always / name).read_bytes() == (never / name).read_bytes(), name
    timing = {"wall_s", "simulation_wall_s", "rtf", "stages_s", "ik_median_ms", "planner"}
    a, b = (json.loads((d / "summary.json").read_text()) for d in (always, never))
    assert {k: v for k, v in a.items() if k not in timing} == {
        k: v for k, v in b.items() if k not in timing
    }


def test_a_run_after_an_in_process_render_draws_its_outputs(tmp_path):
    """A process that has rendered (a notebook, a test suite) keeps a render engine's GL
    state, which a forked helper inherits and then waits on forever at its first render
    (seen as 'the output helper did not answer in 120 s'). The picture is then drawn in
    the process itself, the plot still in its helper, and the run ends."""
    script = (
        "import sys\n"
        "sys.path.insert(0, sys.argv[1])\n"
        "from tests.helpers import scenario\n"
        "from cake_drake.pipeline import run\n"
        "from cake_drake.outputs import worker\n"
        "from cake_drake.world.render import Renderer\n"
        "Renderer(['a']).render({})\n"
        "forked = []\n"
        "class Seen(worker.OutputWorker):\n"
        "    def __init__(self, *a, **k):\n"
        "        super().__init__(*a, **k)\n"
        "        forked.append((self._picture is not None, self._plot is not None))\n"
        "worker.OutputWorker = Seen\n"
        "result = run(scenario('position', folder=sys.argv[2], helpers='always'))\n"
        "print(result.success, forked)\n"
    )
    r = subprocess.run(
        [sys.executable, "-c", script, str(ROOT), str(tmp_path / "out")],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.split() == ["True", "[(False,", "True)]"], r.stdout  # the plot's forked
    assert (tmp_path / "out" / "final_state.png").stat().st_size > 0


def test_no_helpers_are_forked_when_every_core_is_busy():
    """outputs.helpers auto: with a task busy on every core, no core is spare."""
    from cake_drake.outputs.worker import OutputWorker, spare_core

    cores = len(os.sched_getaffinity(0))
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(cores)]
    try:
        deadline = time.monotonic() + 60  # until the busy loops are all running
        while spare_core():
            assert time.monotonic() < deadline, "a core stayed free beside the busy loops"
            time.sleep(0.05)
        worker = OutputWorker(["a"], {}, render=False, helpers="auto")
        assert not worker.forked
        worker.close()
    finally:
        for p in busy:
            p.kill()
            p.wait()


def test_a_bad_helpers_choice_is_one_line_before_anything_runs(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("outputs:\n  helpers: sometimes\n")
    command = ["--scenario", str(bad), "--out", str(tmp_path / "o")]
    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.run", *command], capture_output=True, text=True
    )
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "outputs.helpers 'sometimes'; choose one of: auto, always, never" in r.stderr
    assert not (tmp_path / "o").exists()


def test_a_run_with_output_helpers_leaves_nothing_in_tmpdir(tmp_path):
    # The cake is asked for once, while the world is simulated; asking again at the end
    # (it was not drawn yet: a short run) drew a second one into a folder nobody removed.
    (tmp_path / "s.yaml").write_text("outputs: {helpers: always, render: false}\n")
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.run", "--scenario", "s.yaml", "--mode", "position",
         "--problem", str(VARIANTS.parent / "stack2.pddl"), "--out", "out"],
        cwd=tmp_path, capture_output=True, text=True, timeout=300,
        env={**os.environ, "TMPDIR": str(tmp)},
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "out" / "cake.png").is_file()
    assert list(tmp.iterdir()) == []
