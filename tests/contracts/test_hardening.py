"""Bad input, full disks and signals: one line, a documented exit code, nothing half-written.

The fuzz tests here draw a few hundred mutations per parser on every run;
``benchmarks/fuzz.py`` runs the same mutations by the ten thousand.
"""

from __future__ import annotations

import os
import re
import resource
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydrake.math import RigidTransform

from cake_drake.commands.plan import main_plan
from cake_drake.commands.saycan import main_saycan
from cake_drake.commands.validate import main_validate
from cake_drake.errors import InputError, run_cli
from cake_drake.outputs.files import MARKER, OutputDir
from cake_drake.pipeline import check
from cake_drake.scenario import Recorded, Scenario
from cake_drake.symbolic import BLOCKSWORLD_DOMAIN, MODELS_DIR, PROBLEM_5
from cake_drake.world.facts import read_facts
from tests.helpers import ROOT

EXIT_CODES = {0, 1, 2, 3, 4, 130}
PLAN_5 = "(unstack a b)\n(put-down a)\n(unstack b c)\n(put-down b)\n(pick-up c)\n"
TRANSCRIPT = (MODELS_DIR / "transcripts" / "bring_apple.txt").read_text()
ALPHABET = "()-:?; \n\tabcdefgh0123456789.,'\u2019"


@st.composite
def mutated(draw, text: str) -> str:
    """``text`` with a few random edits: deletions, insertions, duplications, swaps."""
    out = text
    for _ in range(draw(st.integers(1, 6))):
        i = draw(st.integers(0, len(out)))
        kind = draw(st.sampled_from(["delete", "insert", "duplicate", "cut"]))
        if kind == "delete" and out:
            j = min(len(out), i + draw(st.integers(1, 8)))
            out = out[:i] + out[j:]
        elif kind == "insert":
            out = out[:i] + draw(st.text(ALPHABET, min_size=1, max_size=8)) + out[i:]
        elif kind == "duplicate":
            j = min(len(out), i + draw(st.integers(1, 40)))
            out = out[:j] + out[i:j] + out[j:]
        else:
            out = out[:i]
    return out


def _one_line_or_nothing(capsys) -> None:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    errors = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(errors) <= 1, err


FUZZ = settings(
    max_examples=150,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


@FUZZ
@given(domain=mutated(BLOCKSWORLD_DOMAIN.read_text()), problem=mutated(PROBLEM_5.read_text()))
def test_mutated_pddl_never_escapes_the_exit_code_table(domain, problem, tmp_path, capsys):
    d, p, plan = tmp_path / "d.pddl", tmp_path / "p.pddl", tmp_path / "plan.txt"
    d.write_text(domain)
    p.write_text(problem)
    plan.write_text(PLAN_5)
    assert run_cli(main_validate, [str(d), str(p), str(plan)]) in EXIT_CODES
    _one_line_or_nothing(capsys)


@FUZZ
@given(plan=mutated(PLAN_5 + "; cost = 5 (unit cost)\n"))
def test_mutated_plan_files_never_escape_the_exit_code_table(plan, tmp_path, capsys):
    f = tmp_path / "plan.txt"
    f.write_text(plan)
    code = run_cli(main_validate, [str(BLOCKSWORLD_DOMAIN), str(PROBLEM_5), str(f)])
    assert code in EXIT_CODES
    _one_line_or_nothing(capsys)


@FUZZ
@given(transcript=mutated(TRANSCRIPT))
def test_mutated_transcripts_never_escape_the_exit_code_table(transcript, tmp_path, capsys):
    f = tmp_path / "t.txt"
    f.write_text(transcript)
    code = run_cli(main_saycan, [str(f), "--out", str(tmp_path / "out"), "--planner", "gbfs-ff"])
    assert code in EXIT_CODES
    _one_line_or_nothing(capsys)


def test_deeply_nested_pddl_is_one_line(tmp_path, capsys):
    p = tmp_path / "deep.pddl"
    p.write_text("(define (problem p) (:domain blocksworld) (:goal " + "(and " * 5000 + "))")
    assert run_cli(main_plan, [str(BLOCKSWORLD_DOMAIN), str(p)]) == 2
    assert "nested more than 64 deep" in capsys.readouterr().err


def test_a_huge_input_is_refused_unread(tmp_path, capsys):
    p = tmp_path / "huge.pddl"
    with p.open("wb") as f:
        f.truncate(17 * 2**20)
    assert run_cli(main_plan, [str(BLOCKSWORLD_DOMAIN), str(p)]) == 2
    assert "too large" in capsys.readouterr().err


# --- outputs as one transaction ---------------------------------------------------------


def _old_run(folder: Path) -> dict[str, str]:
    folder.mkdir()
    (folder / MARKER).write_text("")
    (folder / "summary.json").write_text('{"old": true}')
    (folder / "replay.html").write_text("old replay")
    return _snapshot(folder)


def _snapshot(folder: Path) -> dict[str, str]:
    return {p.name: p.read_text(errors="replace") for p in sorted(folder.iterdir())}


def _no_leftovers(folder: Path) -> None:
    assert not [p for p in folder.iterdir() if p.name.startswith((".staging-", ".old-"))]


def test_a_commit_replaces_the_folder_whole(tmp_path):
    out = tmp_path / "out"
    _old_run(out)
    with OutputDir(out) as staged:
        staged.write_text("plan.txt", "(pick-up a)\n")
        staged.commit()
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "plan.txt"]  # no old replay
    _no_leftovers(out)


def test_a_failure_while_staging_leaves_the_old_folder_as_it_was(tmp_path):
    out = tmp_path / "out"
    before = _old_run(out)
    with pytest.raises(RuntimeError), OutputDir(out) as staged:
        staged.write_text("summary.json", "{}")
        raise RuntimeError("the renderer failed")
    assert _snapshot(out) == before
    _no_leftovers(out)


def test_a_folder_of_other_files_is_kept_around_the_outputs(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    s = Scenario()
    s.outputs.folder = str(tmp_path)
    check(s)  # kept, not refused: the run replaces only what it wrote
    (tmp_path / "plan.txt").write_text("my plan")
    with pytest.raises(InputError, match="plan.txt: written by you"):
        check(s)


def test_staging_left_by_a_killed_process_is_removed(tmp_path):
    out = tmp_path / "out"
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True).stdout.strip()  # fmt: skip
    out.mkdir()
    leftover = out / f".staging-{dead}"
    leftover.mkdir()
    OutputDir(out).discard()
    assert not leftover.exists()


def _limit_file_size(limit: int):
    def apply() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails instead
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return apply


def test_a_full_disk_leaves_the_saycan_folder_as_it_was(tmp_path):
    out = tmp_path / "out"
    before = _old_run(out)
    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.saycan", "--out", str(out),
         str(MODELS_DIR / "transcripts" / "bring_apple.txt")],
        capture_output=True, text=True, preexec_fn=_limit_file_size(600), cwd=ROOT,
    )  # fmt: skip
    assert r.returncode == 4, r.stderr
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
    assert _snapshot(out) == before
    _no_leftovers(out)


def test_a_full_disk_never_leaves_a_half_written_plan(tmp_path):
    plan = tmp_path / "plan.txt"
    plan.write_text("old plan\n")
    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.plan", "-o", str(plan)],
        capture_output=True, text=True, preexec_fn=_limit_file_size(100), cwd=ROOT,
    )  # fmt: skip
    assert r.returncode == 4, r.stderr
    assert plan.read_text() == "old plan\n"
    assert not list(tmp_path.glob(".plan.txt*"))


# --- facts read back completely -----------------------------------------------------------


def test_the_arm_state_is_read_from_the_fingers_and_the_cube_poses():
    X_WG = RigidTransform([0.5, 0.0, 0.2])
    poses = {"a": RigidTransform([0.5, 0.0, 0.2]), "b": RigidTransform([0.5, 0.1, 0.02])}
    held = read_facts(poses, X_WG=X_WG, finger_opening=0.02).facts
    assert ("holding", "a") in held and ("arm-empty",) not in held
    assert ("on-table", "b") in held and ("clear", "b") in held
    open_hand = read_facts(poses, X_WG=X_WG, finger_opening=0.04)
    assert ("arm-empty",) in open_hand.facts and ("holding", "a") not in open_hand.facts
    away = read_facts({"b": poses["b"]}, X_WG=X_WG, finger_opening=0.0).facts
    assert ("arm-empty",) in away


# --- recorded references --------------------------------------------------------------


@pytest.mark.parametrize(
    "change, words",
    [
        (lambda d: d.update(phase=np.full(6, 9)), "'phase' must be whole numbers from 0 to 6"),
        (lambda d: d.update(action=np.full(6, 4)), "'action' must be whole numbers from -1"),
        (lambda d: d.update(gripper=np.zeros((6, 2))), "'gripper' has shape (6, 2); expected (N,)"),
        (lambda d: d.update(gripper=np.full(6, np.nan)), "'gripper' must be finite"),
    ],
)
def test_a_recorded_reference_with_bad_labels_is_refused_up_front(tmp_path, change, words):
    data = {
        "t": np.arange(6) * 0.1, "q": np.zeros((6, 7)), "gripper": np.full(6, 0.04),
        "phase": np.zeros(6, int), "action": np.full(6, -1), "actions": np.array(["(pick-up a)"]),
    }  # fmt: skip
    change(data)
    np.savez(tmp_path / "t.npz", **data)
    s = Scenario(reference=Recorded(str(tmp_path / "t.npz")))
    with pytest.raises(InputError, match=re.escape(words)):
        check(s, write=False)


# --- signals ------------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_mid_run_stops_cleanly_and_keeps_the_old_outputs(tmp_path, sig):
    out = tmp_path / "out"
    before = _old_run(out)
    # A minute of settling after the last action: however fast the machine, the run is
    # still simulating when its first progress line arrives and the signal follows.
    scenario = tmp_path / "long.yaml"
    scenario.write_text("simulation: {settle_s: 60}\n")
    proc = subprocess.Popen(
        [sys.executable, "-m", "cake_drake.run", "--scenario", str(scenario), "--out", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
        start_new_session=True,
    )  # fmt: skip
    seen = []
    while not any(line.startswith("simulating") for line in seen):  # the run's own signal
        line = proc.stderr.readline()
        assert line, f"the run ended before it simulated: {''.join(seen)}"
        seen.append(line)
    assert proc.poll() is None, "the run ended before the signal"
    os.killpg(proc.pid, sig)  # as a terminal's Ctrl-C does: the whole process group
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "Traceback" not in err, err
    assert err.splitlines()[-1].startswith("error: interrupted"), err
    assert all(line.startswith("simulating") for line in err.splitlines()[:-1]), err
    assert _snapshot(out) == before
    _no_leftovers(out)


def test_an_interrupt_that_lands_where_python_cannot_raise_still_stops_the_command():
    """A signal whose KeyboardInterrupt is raised inside a weak reference's callback or a
    ``__del__`` (the import system's locks have such callbacks) is printed and dropped by
    Python; the command must still stop, as interrupted, not run to its end."""
    script = (
        "import os, signal, time\n"
        "from cake_drake.errors import run_cli\n"
        "class Dropped:\n"
        "    def __del__(self):\n"
        "        os.kill(os.getpid(), signal.SIGINT)\n"
        "        for _ in range(10**6): pass\n"  # the handler runs in here
        "def main(argv):\n"
        "    Dropped()\n"
        "    end = time.monotonic() + 20\n"
        "    while time.monotonic() < end: time.sleep(0.01)\n"
        "    print('ran to its end')\n"
        "    return 0\n"
        "raise SystemExit(run_cli(main, []))\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, cwd=ROOT, timeout=60
    )
    assert proc.returncode == 130, proc.stdout + proc.stderr
    assert "ran to its end" not in proc.stdout
    assert proc.stderr.splitlines()[-1] == "error: interrupted; nothing was written", proc.stderr


@pytest.mark.slow
def test_a_goal_about_the_arm_is_judged_from_the_world(tmp_path):
    from cake_drake.pipeline import run

    p = tmp_path / "p.pddl"
    p.write_text(
        "(define (problem arm) (:domain blocksworld) (:objects a b)\n"
        "  (:init (on-table a) (on-table b) (clear a) (clear b) (arm-empty))\n"
        "  (:goal (and (on a b) (arm-empty))))\n"
    )
    s = Scenario()
    s.task.problem = str(p)
    result = run(s, write=False)
    assert result.success, result.message
    assert ("arm-empty",) in result.execution.reading.facts


def test_a_dead_output_helper_is_reported_not_waited_for(tmp_path):
    """The plot's helper killed mid-run: waiting for it reports the helper's death (its
    exit code), not a helper that did not answer in time."""
    from cake_drake.outputs.worker import OutputWorker

    worker = OutputWorker(["a"], {}, render=False, helpers="always")
    try:
        worker._plot.process.kill()
        worker._plot.process.join(5)
        worker.submit_plot(path=tmp_path / "p.png")
        with pytest.raises(
            RuntimeError, match=r"output helper stopped \(exit code -9\) before writing the plot"
        ):
            worker.wait(timeout_s=30)  # a timeout would say "did not answer"
    finally:
        worker.close()
