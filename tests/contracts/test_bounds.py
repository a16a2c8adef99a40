"""Every input bounded before work, and sweeps checked like runs.

Each case is a small file that would cost a user an hour, a MemoryError or a traceback
if it were read, expanded or run first and checked after.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cake_drake.errors import InputError
from tests.helpers import ROOT

SMOKE = ROOT / "models" / "sweeps" / "smoke.yaml"

BOMB = """\
a: &a {x: 1, y: 1, z: 1, w: 1, v: 1, u: 1, t: 1, s: 1, r: 1}
b: &b {<<: *a, p: [*a, *a, *a, *a, *a, *a, *a, *a, *a]}
c: &c {p: [*b, *b, *b, *b, *b, *b, *b, *b, *b]}
d: &d {p: [*c, *c, *c, *c, *c, *c, *c, *c, *c]}
e: &e {p: [*d, *d, *d, *d, *d, *d, *d, *d, *d]}
f: &f {p: [*e, *e, *e, *e, *e, *e, *e, *e, *e]}
g: &g {p: [*f, *f, *f, *f, *f, *f, *f, *f, *f]}
"""


def cake(command: str, *args: str, cwd: Path, timeout: float = 120):
    return subprocess.run(
        [sys.executable, "-m", f"cake_drake.{command}", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )


def refused(r, *words: str) -> None:
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr and r.stderr.count("\n") == 1, r.stderr
    for w in words:
        assert w in r.stderr, r.stderr


@pytest.mark.parametrize(
    "text, words",
    [
        (BOMB, ["aliases and merge keys expand to more than 100,000"]),
        ("seed: " + "9" * 400 + "\n", ["s.yaml:1: seed = ", "out of range"]),
        ("world: {time_step: 1" + "0" * 400 + "}\n", ["is not a finite number"]),
        ("task:\n  generate: {blocks: 3000000}\n", ["task.generate.blocks = 3000000 is outside"]),
    ],
    ids=["alias bomb", "400 digits", "huge float", "3 million blocks"],
)
def test_a_scenario_that_would_expand_or_overflow_is_refused_fast(tmp_path, text, words):
    (tmp_path / "s.yaml").write_text(text)
    refused(cake("run", "--scenario", "s.yaml", "--out", "o", cwd=tmp_path), *words)
    assert not (tmp_path / "o").exists()


def test_a_device_as_a_scenario_or_sweep_is_refused_unread(tmp_path):
    refused(cake("run", "--scenario", "/dev/zero", cwd=tmp_path), "is a device")
    refused(cake("sweep", "/dev/zero", cwd=tmp_path), "is a device")


def test_a_scenario_over_16_mib_is_refused_unread(tmp_path):
    big = tmp_path / "big.yaml"
    with big.open("w") as f:
        f.write("seed: 1\n")
        f.write("#" * (17 * 2**20) + "\n")
    refused(cake("run", "--scenario", "big.yaml", cwd=tmp_path), "too large")


@pytest.mark.parametrize(
    "text, words",
    [
        ("seeds: 1000000000\n", ["seeds = 1000000000 is more than 10,000 runs"]),
        (
            "grid:\n  seed: [{}]\n  world.time_step: [{}]\n".format(
                ", ".join(str(i) for i in range(1000)), ", ".join(["0.01"] * 1000)
            ),
            ["1,000,000 runs (cases x grid x seeds) is more than one sweep holds"],
        ),
        ("grid:\n  world.time_step: [0.01, 100]\n", ["grid world.time_step = 100", "outside"]),
        ("grid:\n  task.planner: [auto, nosuch]\n", ["grid task.planner = nosuch", "unknown"]),
        (
            "cases:\n  - {name: far, world.slot_radius: 5}\n",
            ["case far", "world.slot_radius = 5.0 is outside"],
        ),
    ],
    ids=["a billion seeds", "a million-run grid", "bad time step", "bad planner", "bad case"],
)
def test_a_sweep_is_checked_like_its_runs_before_anything_runs(tmp_path, text, words):
    (tmp_path / "sweep.yaml").write_text(text)
    r = cake("sweep", "sweep.yaml", "--out", "out", "--quiet", cwd=tmp_path)
    refused(r, *words)
    assert not (tmp_path / "out").exists()  # refused before any run or folder


def test_an_npz_whose_arrays_are_huge_is_refused_by_its_headers(tmp_path):
    np.savez_compressed(
        tmp_path / "bomb.npz", t=np.zeros(4), q=np.zeros((50_000_000, 7)), gripper=np.zeros(4)
    )
    assert (tmp_path / "bomb.npz").stat().st_size < 5 * 2**20
    r = cake("run", "--reference", "bomb.npz", cwd=tmp_path)
    refused(r, "its arrays hold more than 256 MiB", "'q' has shape (50000000, 7)")


def test_resume_reruns_rows_that_are_not_rows(tmp_path):
    from cake_drake.sweeps.driver import _rows_on_disk

    runs = tmp_path / "runs"
    for name, text in [("a", "[]"), ("b", '{"status": "done"}'), ("c", "\xff"), ("d", None)]:
        (runs / name).mkdir(parents=True)
        if text is not None:
            (runs / name / "row.json").write_text(text, encoding="latin-1")
    (runs / "e").mkdir()
    (runs / "e" / "row.json").write_text(json.dumps({"run_id": "e", "status": "done"}))
    assert list(_rows_on_disk(tmp_path)) == ["e"]


def _children(pid: int) -> list[int]:
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return found


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"  # a zombie has ended; only its parent's reaping is left


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads /proc")
def test_the_workers_of_a_killed_sweep_die_with_it(tmp_path):
    # A sweep killed outright cannot remove its scratch folder: it is left in the test's.
    proc = subprocess.Popen(
        [sys.executable, "-m", "cake_drake.sweep", str(SMOKE), "--out", "out", "--workers", "1"],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT), "TMPDIR": str(tmp_path)},
    )  # fmt: skip
    workers: list[int] = []
    deadline = time.monotonic() + 120
    while not workers:  # the sweep's own signal: its worker process is there
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "no worker started"
        workers = [
            p
            for p in _children(proc.pid)
            if b"spawn_main" in Path(f"/proc/{p}/cmdline").read_bytes()
        ]
        time.sleep(0.1)
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=60)
    deadline = time.monotonic() + 60
    while any(_alive(w) for w in workers):
        assert time.monotonic() < deadline, "a worker outlived its sweep"
        time.sleep(0.1)


@pytest.mark.alone
@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_to_a_sweeps_process_group_prints_one_line(tmp_path, sig):
    """As a terminal's Ctrl-C does: every process of the sweep gets the signal; the user
    sees one line, never a helper's BrokenPipeError."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "cake_drake.sweep", str(SMOKE), "--out", "out", "--quiet",
         "--workers", "2"],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)}, start_new_session=True,
    )  # fmt: skip
    deadline = time.monotonic() + 300
    while not list((tmp_path / "out").glob("runs/*/row.json")):  # the first run finished
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "no run finished"
        time.sleep(0.1)
    os.killpg(proc.pid, sig)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "BrokenPipeError" not in err, err
    assert err.splitlines() == ["error: interrupted: what finished is kept; --resume runs the rest"]


def test_a_file_where_a_sweep_keeps_a_runs_folder_is_exit_2_up_front(tmp_path):
    from cake_drake.sweeps import LocalPool, load_sweep, run_sweep
    from cake_drake.sweeps.driver import prepare

    sweep = load_sweep(SMOKE)
    out = tmp_path / "out"
    run_id = prepare(sweep, out)[0]["id"]
    from cake_drake.outputs.files import claim_folder
    from cake_drake.sweeps.driver import SWEEP_OUTPUTS

    claim_folder(out, "sweep", SWEEP_OUTPUTS)  # an earlier sweep's folder
    (out / "runs").mkdir()
    (out / "runs" / run_id).write_text("in the way")
    with pytest.raises(InputError, match="a file where the sweep keeps a run's folder"):
        run_sweep(sweep, out, LocalPool(1), progress=False)
    kept = {str(p.relative_to(out)) for p in out.rglob("*")}
    assert kept == {".cake_drake-outputs", "runs", f"runs/{run_id}"}  # nothing written


#: A planner that will not be told: it ignores SIGTERM and sleeps (a plug-in stuck in
#: C code, or one that installs its own handler, is the same to the sweep).
STUBBORN = """
import pathlib
import signal
import time


def plan(problem, time_limit):
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    pathlib.Path("stubborn.started").touch()
    time.sleep(600)
"""


@pytest.mark.alone
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_sweep_whose_worker_ignores_sigterm_still_ends_on_a_signal(tmp_path, sig):
    """Workers told, joined with a deadline, then killed: the sweep's end never waits on a
    worker that does not end when told (nor on a pipe it left half-written)."""
    (tmp_path / "stubborn.py").write_text(STUBBORN)
    (tmp_path / "s.yaml").write_text(
        "scenario:\n  task: {planner: 'stubborn:plan', generate: {blocks: 3}}\n"
        "  outputs: {render: false}\ngrid:\n  task.generate.seed: [1]\n"
    )
    proc = subprocess.Popen(
        [sys.executable, "-m", "cake_drake.sweep", "s.yaml", "--out", "out", "--quiet",
         "--workers", "1"],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(ROOT)])},
        start_new_session=True,
    )  # fmt: skip
    deadline = time.monotonic() + 300
    while not (tmp_path / "stubborn.started").exists():  # the worker is in the plug-in
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "the plug-in never started"
        time.sleep(0.1)
    os.killpg(proc.pid, sig)
    try:
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, err
    assert err.splitlines() == ["error: interrupted: what finished is kept; --resume runs the rest"]


def test_spawn_imap_yields_each_answer_and_names_a_failing_job():
    from cake_drake.sweeps import spawn_imap
    from cake_drake.sweeps.pool import WorkerFailed

    assert sorted(spawn_imap(math.sqrt, [1.0, 4.0, 9.0], 2)) == [1.0, 2.0, 3.0]
    with pytest.raises(WorkerFailed, match="math domain error"):
        list(spawn_imap(math.sqrt, [4.0, -1.0], 2))


def _entry_points() -> list[list[str]]:
    """Every command: each ``python -m cake_drake.X`` module, and the console script."""
    found = []
    for path in sorted((ROOT / "cake_drake").rglob("*.py")):
        text = path.read_text()
        command = "cake_drake.commands" in text or "cake_drake.cli" in text
        if 'if __name__ == "__main__":' not in text or not command:
            continue  # not a command (processes.py's guard is a script, not a command)
        parts = path.relative_to(ROOT).with_suffix("").parts
        parts = parts[:-1] if parts[-1] == "__main__" else parts
        found.append(["-m", ".".join(parts)])
    script = Path(sys.executable).parent / "cake-drake"
    if script.is_file():
        found.append([str(script), "run"])
    return found


@pytest.mark.parametrize("entry", _entry_points(), ids=lambda e: e[-1].rsplit("/", 1)[-1])
def test_ctrl_c_while_a_command_starts_is_one_line_and_130(tmp_path, entry):
    """Ctrl-C during a command's imports (before its main runs): stopped at several points
    of the imports, read from ``-X importtime`` (no clock: each is a point the command has
    reached), never a KeyboardInterrupt traceback."""
    for after in (1, 10, 40):  # import lines after the package's own
        proc = subprocess.Popen(
            [sys.executable, "-X", "importtime", *entry],
            cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
        )  # fmt: skip
        seen = None
        for line in proc.stderr:
            if seen is None and line.split("|")[-1].strip() == "cake_drake":
                seen = 0
            elif seen is not None and line.startswith("import time:"):
                seen += 1
                if seen == after:
                    proc.send_signal(signal.SIGINT)
                    break
        out, err = proc.communicate(timeout=120)
        err = "\n".join(x for x in err.splitlines() if not x.startswith("import time:"))
        assert seen == after, f"{entry}: the imports ended before the signal"
        assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
        assert proc.returncode == 130, (after, err)
        assert err.strip().splitlines()[-1].startswith("error: interrupted"), err
