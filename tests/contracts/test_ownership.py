"""Nothing the user owns is lost: a command replaces only what it wrote, and says so first.

Each case is one a user can hit: output folders of different commands inside each other,
an input inside the output folder, a link as the output folder, a special file as a
target, ``~`` in a path, closed standard streams, a pipe as the problem.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from cake_drake.errors import InputError
from cake_drake.outputs.files import MARKER, OutputDir, check_output_folder
from cake_drake.symbolic import MODELS_DIR, PROBLEM_5
from tests.helpers import ROOT

TRANSCRIPT = MODELS_DIR / "transcripts" / "bring_apple.txt"


def cake(*args: str, cwd: Path, env: dict | None = None, stdout=subprocess.PIPE, **kw):
    command, *rest = args
    return subprocess.run(
        [sys.executable, "-m", f"cake_drake.{command}", *rest],
        cwd=cwd,
        stdout=stdout,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT), **(env or {})},
        timeout=300,
        **kw,
    )


def snapshot(folder: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(folder)): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file() and not p.name.startswith(".")
    }


def one_error_line(r) -> None:
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr and r.stderr.count("\n") == 1, r.stderr


def test_a_run_keeps_the_saycan_report_it_did_not_write(tmp_path):
    """The default folders nest (outputs/ and outputs/saycan/...): the run keeps the report."""
    r = cake("saycan", str(TRANSCRIPT), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    report = tmp_path / "outputs" / "saycan" / "bring_apple"
    before = snapshot(report)
    assert "report.md" in before
    r = cake("run", "--quiet", "--no-render", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert snapshot(report) == before
    assert (tmp_path / "outputs" / "summary.json").is_file()
    # and the next run replaces the run's files only, never the report
    r = cake("run", "--quiet", "--no-render", "--mode", "position", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert snapshot(report) == before
    marker = json.loads((tmp_path / "outputs" / MARKER).read_text())
    assert "saycan" not in marker["written"]["run"]


def test_a_folder_with_the_users_own_files_as_input_and_output_is_refused_whole(tmp_path):
    mine = tmp_path / "work"
    mine.mkdir()
    (mine / "problem.pddl").write_bytes(PROBLEM_5.read_bytes())
    (mine / "plan.txt").write_text("(unstack a b)\n")
    (mine / "report.md").write_text("my notes\n")
    before = snapshot(mine)
    r = cake("run", "--problem", "work/problem.pddl", "--out", "work", "--quiet", cwd=tmp_path)
    one_error_line(r)
    assert "work/plan.txt: written by you (not cake_drake)" in r.stderr
    assert snapshot(mine) == before and not (mine / MARKER).exists()


def test_an_input_among_the_outputs_a_run_replaces_is_refused(tmp_path):
    with OutputDir(tmp_path / "out", "run", ["trajectory.npz"]) as staged:
        staged.path("trajectory.npz").write_bytes(b"recorded")
        staged.commit()
    with pytest.raises(InputError, match="an input of this run lies in its output folder"):
        check_output_folder(
            tmp_path / "out", "run", ["trajectory.npz"], [tmp_path / "out" / "trajectory.npz"]
        )


def test_the_users_files_beside_the_outputs_are_kept_and_old_outputs_replaced(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    with OutputDir(out, "run", ["plan.txt", "problem.pddl"]) as staged:
        staged.write_text("plan.txt", "first\n")
        staged.write_text("problem.pddl", "generated\n")
        staged.commit()
    with OutputDir(out, "run", ["plan.txt", "problem.pddl"]) as staged:
        staged.write_text("plan.txt", "second\n")
        staged.commit()
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "notes.txt", "plan.txt"]
    assert (out / "plan.txt").read_text() == "second\n"
    assert (out / "notes.txt").read_text() == "mine"


def test_another_commands_outputs_are_not_replaced_by_a_name_clash(tmp_path):
    out = tmp_path / "out"
    with OutputDir(out, "saycan", ["plan.txt"]) as staged:
        staged.write_text("plan.txt", "transcribed\n")
        staged.commit()
    with pytest.raises(InputError, match="written by the saycan command"):
        OutputDir(out, "run", ["plan.txt"])
    assert (out / "plan.txt").read_text() == "transcribed\n"


def test_a_link_as_the_output_folder_is_written_through_never_moved(tmp_path):
    target = tmp_path / "target"
    target.mkdir()
    link = tmp_path / "link"
    link.symlink_to(target)
    r = cake("run", "--out", "link", "--quiet", "--no-render", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert (target / "summary.json").is_file()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_a_link_to_nowhere_is_refused(tmp_path):
    (tmp_path / "dangling").symlink_to(tmp_path / "gone")
    r = cake("run", "--out", "dangling", "--quiet", cwd=tmp_path)
    one_error_line(r)
    assert "a link to nowhere" in r.stderr


@pytest.mark.parametrize(
    "command",
    [
        ("plan", "-o", "{target}"),
        ("world", "--render", "{target}"),
    ],
    ids=["plan -o", "world --render"],
)
def test_a_special_file_as_a_target_is_refused_and_left_as_it_is(tmp_path, command):
    fifo = tmp_path / "pipe.png"
    os.mkfifo(fifo)
    r = cake(*(a.format(target=fifo) for a in command), cwd=tmp_path)
    one_error_line(r)
    assert "special file" in r.stderr
    assert fifo.exists() and not fifo.is_file()


def test_a_tilde_in_the_output_folder_is_the_home_folder(tmp_path):
    home = tmp_path / "home"
    home.mkdir()
    scenario = tmp_path / "s.yaml"
    scenario.write_text("outputs: {folder: ~/runs/x, render: false}\n")
    r = cake("run", "--scenario", str(scenario), "--quiet", cwd=tmp_path, env={"HOME": str(home)})
    assert r.returncode == 0, r.stderr
    assert (home / "runs" / "x" / "summary.json").is_file()
    assert not (tmp_path / "~").exists()


def test_a_sweep_over_the_users_own_results_table_is_refused_up_front(tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "results.csv").write_text("my,table\n")
    r = cake("sweep", str(ROOT / "models" / "sweeps" / "smoke.yaml"), "--out", "mine",
             "--quiet", cwd=tmp_path)  # fmt: skip
    one_error_line(r)
    assert "mine/results.csv: written by you" in r.stderr
    assert sorted(p.name for p in out.iterdir()) == ["results.csv"]


def test_a_sweep_never_takes_over_a_runs_outputs(tmp_path):
    """A run's folder holds plan.txt etc.; a sweep there keeps them (it writes its own)."""
    out = tmp_path / "out"
    with OutputDir(out, "run", ["plan.txt"]) as staged:
        staged.write_text("plan.txt", "(pick-up a)\n")
        staged.commit()
    from cake_drake.outputs.files import claim_folder
    from cake_drake.sweeps.driver import SWEEP_OUTPUTS

    claim_folder(out, "sweep", SWEEP_OUTPUTS)
    with OutputDir(out, "run", ["plan.txt"]) as staged:  # the next run replaces its own
        staged.write_text("plan.txt", "(pick-up b)\n")
        staged.commit()
    marker = json.loads((out / MARKER).read_text())
    assert marker["written"]["sweep"] == sorted(SWEEP_OUTPUTS)
    assert marker["written"]["run"] == ["plan.txt"]


# --- section 5: refused before simulating; streams; pipes; names -----------------------------


def test_an_output_folder_under_a_regular_file_is_refused_before_simulating(tmp_path):
    (tmp_path / "afile").write_text("")
    r = cake("run", "--out", "afile/x", cwd=tmp_path)
    one_error_line(r)
    assert "is a file, not a folder" in r.stderr
    assert "simulating" not in r.stderr


def test_the_current_folder_as_the_output_folder(tmp_path):
    (tmp_path / "keep.txt").write_text("mine")
    r = cake("run", "--out", ".", "--quiet", "--no-render", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "summary.json").is_file() and (tmp_path / "keep.txt").read_text() == "mine"


@pytest.mark.parametrize("closed", ["stdout", "stderr"])
def test_a_closed_standard_stream_does_not_fail_a_run(tmp_path, closed):
    close = ">&-" if closed == "stdout" else "2>&-"
    r = subprocess.run(
        f"{sys.executable} -m cake_drake.run --no-render --out o {close}",
        shell=True, cwd=tmp_path, capture_output=True, text=True, timeout=300,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "o" / "summary.json").is_file()


def test_a_pipe_as_the_problem_of_a_run(tmp_path):
    r = subprocess.run(
        ["bash", "-c", f"{sys.executable} -m cake_drake.run --quiet --no-render --out o "
         f"--problem <(cat {PROBLEM_5})"],
        cwd=tmp_path, capture_output=True, text=True, timeout=300,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "goal reached" in r.stdout


def test_two_scenarios_of_one_name_are_refused(tmp_path):
    (tmp_path / "dup.yaml").write_text("one:\n  seed: 1\none:\n  seed: 2\n")
    r = cake("run", "--scenario", "dup.yaml", "--name", "one", cwd=tmp_path)
    one_error_line(r)
    assert "dup.yaml:3: scenario 'one' given twice" in r.stderr


def test_a_saycan_goal_with_an_unknown_predicate_is_bad_input(tmp_path):
    (tmp_path / "t.txt").write_text("1. pick up the apple\nGoal: (flying apple)\n")
    r = cake("saycan", "t.txt", "--out", "s", cwd=tmp_path)
    one_error_line(r)
    assert "unknown predicate flying" in r.stderr
    assert not (tmp_path / "s").exists()
