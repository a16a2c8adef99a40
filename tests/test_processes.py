"""Process groups the project owns (`cake_drake.processes`) end with their caller: real
processes, found through Linux's /proc, no mocks."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from cake_drake import processes

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")

#: s a bounded wait polls before it gives up.
WAIT_S = 20.0


def _stat(pid: int) -> tuple[str, int, int] | None:
    """(state, parent, start time) of a process, or None when there is none."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            fields = f.read().rpartition(b")")[2].split()
    except OSError:
        return None
    return fields[0].decode(), int(fields[1]), int(fields[19])


def _cmdline(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            return f.read().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def _alive(ident: tuple[int, int]) -> bool:
    """Whether the process ``(pid, start time)`` still runs (a zombie has ended)."""
    st = _stat(ident[0])
    return st is not None and st[2] == ident[1] and st[0] not in ("Z", "X")


def _descendants(root: int) -> list[tuple[int, int]]:
    """Every process below ``root``, as ``(pid, start time)``."""
    children: dict[int, list[int]] = {}
    starts = {}
    for name in os.listdir("/proc"):
        if name.isdigit() and (st := _stat(int(name))) is not None:
            children.setdefault(st[1], []).append(int(name))
            starts[int(name)] = st[2]
    found, todo = [], [root]
    while todo:
        for pid in children.get(todo.pop(), []):
            found.append((pid, starts[pid]))
            todo.append(pid)
    return found


def _wait_until(condition, what: str, wait_s: float = WAIT_S) -> None:
    deadline = time.monotonic() + wait_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"not within {wait_s:g} s: {what}")
        time.sleep(0.1)


def _kill_all(idents) -> None:
    for ident in idents:
        if _alive(ident):
            os.kill(ident[0], signal.SIGKILL)


# --- the helper itself -----------------------------------------------------------------


def test_output_and_exit_code_are_the_commands():
    code = "import sys; print('out'); print('err', file=sys.stderr); sys.exit(7)"
    with processes.owned(
        [sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    ) as proc:
        out, _ = proc.communicate(timeout=WAIT_S)
    assert proc.returncode == 7
    assert out.split() == ["out", "err"]


def test_a_command_killed_by_a_signal_reads_as_popens():
    code = "import os, signal; os.kill(os.getpid(), signal.SIGUSR1)"
    with processes.owned([sys.executable, "-c", code]) as proc:
        proc.wait(timeout=WAIT_S)
    assert proc.returncode == -signal.SIGUSR1


def test_a_missing_program_is_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError):
        processes.start(["cake-drake-no-such-program"])
    with pytest.raises(FileNotFoundError):
        processes.start([str(tmp_path / "missing")])
    with pytest.raises(TypeError, match="start_new_session"):
        processes.start(["true"], start_new_session=True)


def test_what_the_command_leaves_behind_ends_with_it():
    """A grandchild still holding the output pipe would keep communicate() waiting."""
    with processes.owned(
        ["sh", "-c", "sleep 300 & echo $!"], stdout=subprocess.PIPE, text=True
    ) as proc:
        out, _ = proc.communicate(timeout=WAIT_S)
    pid = int(out)
    _wait_until(lambda: _stat(pid) is None or _stat(pid)[0] == "Z", "the sleep left ended")


@pytest.mark.alone
def test_an_exception_in_the_caller_ends_the_group():
    started = []
    with pytest.raises(RuntimeError), processes.owned(["sh", "-c", "sleep 300 & wait"]) as proc:
        _wait_until(lambda: len(_descendants(proc.pid)) >= 2, "sh and its sleep started")
        started = _descendants(proc.pid)
        raise RuntimeError("the caller fails")
    try:
        _wait_until(lambda: not any(_alive(p) for p in started), "sh and sleep ended")
    finally:
        _kill_all(started)


@pytest.mark.alone
def test_a_caller_that_exits_normally_ends_the_group():
    """A group still running when its caller's interpreter exits ends with it."""
    code = (
        "import subprocess; from cake_drake import processes; "
        "p = processes.start(['sh', '-c', 'sleep 300 & echo $!; wait'], stdout=subprocess.PIPE)"
        "; print(p.pid, int(p.stdout.readline()))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=WAIT_S
    )
    assert done.returncode == 0, done.stderr
    guard, sleep = map(int, done.stdout.split())
    for pid in (guard, sleep):
        _wait_until(lambda pid=pid: _stat(pid) is None or _stat(pid)[0] == "Z", f"{pid} ended")


# --- Fast Downward under `python -m cake_drake.plan` -----------------------------------

#: A task Fast Downward searches for as long as it is let, without a word: 40 switches to
#: turn on and a car to drive a -> b -> c -> d on 2 units of fuel. Only the search finds
#: the fuel short (its heuristics ignore what an action uses up; the translator's
#: invariants do not count), after its log's last line (~40 expansions in): it then walks
#: 2^40 states. Fast Downward on Blocksworld is no test of this: it logs every second or
#: so, and a log line written to its gone caller's pipe ends it.
FUEL_DOMAIN = """(define (domain fuel)
  (:requirements :strips)
  (:predicates (at ?p) (road ?p ?q) (fuel ?f) (less ?f ?g) (switch ?s) (on ?s))
  (:action turn-on :parameters (?s) :precondition (switch ?s) :effect (on ?s))
  (:action drive :parameters (?p ?q ?f ?g)
    :precondition (and (at ?p) (road ?p ?q) (fuel ?f) (less ?g ?f))
    :effect (and (at ?q) (not (at ?p)) (fuel ?g) (not (fuel ?f)))))
"""
SWITCHES = [f"s{i}" for i in range(40)]
FUEL_PROBLEM = f"""(define (problem fuel-short)
  (:domain fuel)
  (:objects a b c d f0 f1 f2 {" ".join(SWITCHES)})
  (:init (at a) (fuel f2) (less f1 f2) (less f0 f1) (road a b) (road b c) (road c d)
    {" ".join(f"(switch {s})" for s in SWITCHES)})
  (:goal (and (at d) {" ".join(f"(on {s})" for s in SWITCHES)})))
"""
#: CPU s the search has used once it is well past its last log line (that comes ~0.01 s in).
SILENT_CPU_S = 0.5
#: s the group has to be gone once the caller has ended (it goes at once: a kill).
GONE_S = 10.0


def _cpu_s(pid: int) -> float:
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            fields = f.read().rpartition(b")")[2].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _searching(caller: int) -> list[tuple[int, int]]:
    """The processes below ``caller`` once Fast Downward's search (the ``downward``
    binary) is in its silent walk, else none."""
    below = _descendants(caller)
    search = [p for p, _ in below if "--search" in _cmdline(p) and _cpu_s(p) >= SILENT_CPU_S]
    return below if search else []


def _in_folder(folder: str) -> list[str]:
    """Every live process working in ``folder`` (Fast Downward's temporary folder, where
    the driver, translate and the search all run, even once it is removed)."""
    found = []
    for name in os.listdir("/proc"):
        try:
            cwd = os.readlink(f"/proc/{name}/cwd")
        except OSError:
            continue
        st = _stat(int(name)) if name.isdigit() else None
        if cwd.startswith(folder) and st is not None and st[0] not in ("Z", "X"):
            found.append(_cmdline(int(name))[:100])
    return found


@pytest.mark.alone
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL], ids=["sigterm", "sigkill"])
def test_fast_downward_ends_with_its_caller(tmp_path, sig):
    """A plan stopped by SIGTERM (exit 130, the interrupted line) or killed by SIGKILL
    (nothing of it runs) leaves no Fast Downward process behind: before, the driver and
    its search ran on, re-parented to init, for as long as the search took."""
    from cake_drake.symbolic import fast_downward

    assert fast_downward.available(), "the fd extra is part of the test extra"
    (tmp_path / "fuel.pddl").write_text(FUEL_DOMAIN)
    (tmp_path / "short.pddl").write_text(FUEL_PROBLEM)
    caller = subprocess.Popen(
        [sys.executable, "-m", "cake_drake.plan", "fuel.pddl", "short.pddl"]
        + ["--planner", "fd-lama-first"],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        # SIGABRT shows where it hangs; a caller killed outright cannot remove its
        # temporary folder, so it makes it here, not in the machine's /tmp.
        env={**os.environ, "PYTHONFAULTHANDLER": "1", "TMPDIR": str(tmp_path)},
    )
    fd: list[tuple[int, int]] = []
    try:
        _wait_until(lambda: bool(_searching(caller.pid)), "the search walks its states")
        fd = _searching(caller.pid)
        paths = [a for p, _ in fd for a in _cmdline(p).split() if "/cake_drake_fd_" in a]
        folder = os.path.dirname(paths[0])  # the run's temporary folder
        os.kill(caller.pid, sig)
        try:
            _, err = caller.communicate(timeout=WAIT_S)
        except subprocess.TimeoutExpired:
            os.kill(caller.pid, signal.SIGABRT)
            _, err = caller.communicate(timeout=WAIT_S)
            raise AssertionError(f"the caller did not end within {WAIT_S:g} s: {err}") from None
        if sig == signal.SIGTERM:
            assert caller.returncode == 130, err
            assert err.strip() == "error: interrupted by SIGTERM; nothing was written", err
        else:
            assert caller.returncode == -signal.SIGKILL
        deadline = time.monotonic() + GONE_S
        while (any(_alive(p) for p in fd) or _in_folder(folder)) and time.monotonic() < deadline:
            time.sleep(0.1)
        left = sorted({_cmdline(p[0])[:100] for p in fd if _alive(p)} | set(_in_folder(folder)))
        assert not left, f"still running {GONE_S:g} s after the caller ended: {left}"
    finally:
        caller.kill()
        caller.wait()
        _kill_all(fd)


@pytest.mark.alone
def test_fast_downward_time_limit_is_a_limit_and_leaves_nothing(tmp_path, monkeypatch):
    """The wall-clock limit: status ``limit`` after it, the whole group killed."""
    import tempfile

    from cake_drake.symbolic import fast_downward, parse_domain, parse_problem

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # Fast Downward's folder here
    problem = parse_problem(parse_domain(FUEL_DOMAIN), FUEL_PROBLEM)
    result = fast_downward.run(problem, "lama-first", "fd-lama-first", 1.0)
    assert result.status == "limit" and result.time_s >= 1.0
    _wait_until(lambda: not _in_folder(str(tmp_path)), "Fast Downward ended")
