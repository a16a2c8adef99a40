"""Work spread over spawned worker processes on this machine, with an end that always comes.

One pipe per worker and no thread in the calling process: the caller's own thread hands
out the jobs, reads the answers and, whatever stops it (the last answer, an exception,
Ctrl-C or SIGTERM raised as an interrupt), ends the workers itself, within a deadline:
told to stop (an idle worker is told by its pipe, a busy one by SIGTERM), joined for
:data:`STOP_S`, then killed. Nothing is left for the interpreter's exit to wait on.

:func:`spawn_events` is the engine (the sweep's :class:`~cake_drake.sweeps.LocalPool`
reads it); :func:`spawn_imap` is the same pool for any work: ``fn(job)`` for every job,
yielded as each finishes.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from multiprocessing.connection import wait

from cake_drake.errors import CakeDrakeError

#: s the workers have to end once told, before they are killed.
STOP_S = 5.0
#: s to wait for a killed worker to be gone (it does at once, unless the kernel holds it).
KILL_WAIT_S = 5.0


class WorkerDied(CakeDrakeError):
    """A worker process ended (a crash, or it was killed) while it ran a job."""


class WorkerFailed(CakeDrakeError):
    """``fn`` raised in a worker: its exception, as a line, with the worker's traceback."""

    def __init__(self, message: str, trace: str) -> None:
        super().__init__(message)
        self.trace = trace


def quiet_worker(parent: int | None = None) -> None:
    """In a worker: Ctrl-C is left to the parent, which stops the workers itself, and the
    worker ends with its parent: on Linux the kernel kills a worker whose parent is gone
    (even by SIGKILL), and a worker whose parent was already gone when it started ends at
    once."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    try:
        import ctypes

        PR_SET_PDEATHSIG = 1
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):  # not Linux: the pipe's end of file ends it later
        pass
    if parent is not None and os.getppid() != parent:
        os._exit(1)


def _serve(conn, fn: Callable, parent: int) -> None:
    """A worker's loop: a job in, ``("ok", answer)`` or ``("error", line, trace)`` out,
    until ``None`` or the parent's end of the pipe closes."""
    quiet_worker(parent)
    while True:
        try:
            job = conn.recv()
        except (EOFError, OSError):
            return
        if job is None:
            return
        try:
            reply = ("ok", fn(job))
        except BaseException as e:  # noqa: BLE001 - reported to the parent, which decides
            text = (str(e).strip().splitlines() or [""])[0]
            line = f"{type(e).__name__}: {text}" if text else type(e).__name__
            reply = ("error", line, "".join(traceback.format_exception(e)))
        conn.send(reply)


class _Worker:
    def __init__(self, ctx, fn: Callable) -> None:
        self.conn, child = ctx.Pipe()
        self.process = ctx.Process(target=_serve, args=(child, fn, os.getpid()))
        self.process.start()
        child.close()  # the worker's end lives in the worker alone: its death is an EOF here
        self.job = None


def _end(workers: list[_Worker], told: bool) -> None:
    """Every worker gone within :data:`STOP_S` + :data:`KILL_WAIT_S`: told (``None`` down
    an idle one's pipe when ``told``, else SIGTERM), joined until the deadline, then
    killed. Nothing here waits without a bound."""
    for w in workers:
        try:
            if told and w.job is None:
                w.conn.send(None)
            else:
                w.process.terminate()
        except (OSError, ValueError):  # the pipe or the process is gone already
            pass
    deadline = time.monotonic() + STOP_S
    for w in workers:
        w.process.join(max(0.0, deadline - time.monotonic()))
    late = [w for w in workers if w.process.exitcode is None]
    for w in late:
        w.process.kill()
    deadline = time.monotonic() + KILL_WAIT_S
    for w in late:
        w.process.join(max(0.0, deadline - time.monotonic()))
    for w in workers:
        w.conn.close()


def spawn_events(fn: Callable, jobs: Sequence, workers: int) -> Iterator[tuple]:
    """``fn(job)`` for every job on ``workers`` spawned processes (no more than there are
    jobs), as events: ``("start", job)`` when a worker takes it, then ``("done", job,
    answer)``, ``("error", job, WorkerFailed)`` when ``fn`` raised, or ``("died", job)``
    when the worker died running it (a fresh worker takes the next job). ``fn`` must be
    importable by name (a module's function). Whatever ends the iteration (the last event,
    ``close()``, an exception or an interrupt in the caller), the workers are gone after it,
    within a deadline (:func:`_end`)."""
    ctx = multiprocessing.get_context("spawn")
    queue = deque(jobs)
    pool: list[_Worker] = []
    told = False
    try:
        while queue or any(w.job is not None for w in pool):
            while queue and (len(pool) < workers or any(w.job is None for w in pool)):
                idle = [w for w in pool if w.job is None]  # else room for a new worker
                w = idle[0] if idle else _Worker(ctx, fn)
                if not idle:
                    pool.append(w)
                try:
                    w.conn.send(queue[0])
                except OSError:  # it ended while idle: a fresh one takes the job
                    pool.remove(w)
                    _end([w], told=False)
                    continue
                w.job = queue.popleft()
                yield ("start", w.job)
            busy = [w for w in pool if w.job is not None]
            ready = wait([w.conn for w in busy] + [w.process.sentinel for w in busy])
            for w in busy:
                if w.conn not in ready and w.process.sentinel not in ready:
                    continue
                job, w.job = w.job, None
                try:
                    reply = w.conn.recv() if w.conn.poll() else None
                except (EOFError, OSError):
                    reply = None
                if reply is None or w.process.sentinel in ready:  # it ended: replaced
                    pool.remove(w)
                    _end([w], told=False)
                if reply is None:
                    yield ("died", job)
                elif reply[0] == "ok":
                    yield ("done", job, reply[1])
                else:
                    yield ("error", job, WorkerFailed(reply[1], reply[2]))
        told = True
    finally:
        _end(pool, told)


def spawn_imap(fn: Callable, jobs: Sequence, workers: int) -> Iterator:
    """``fn(job)`` for every job on a local pool of ``workers`` spawned processes, yielded
    as each finishes (in the order they finish). ``fn`` raising in a worker raises
    :class:`WorkerFailed` here, a worker that dies :class:`WorkerDied`; on these, on
    Ctrl-C or SIGTERM (as an interrupt) and on ``close()``, the workers are told, joined
    with a deadline, then killed, before the exception goes on."""
    for event in spawn_events(fn, jobs, workers):
        if event[0] == "done":
            yield event[2]
        elif event[0] == "error":
            raise event[2]
        elif event[0] == "died":
            raise WorkerDied(
                f"a worker process died while running job {event[1]!r} (a crash, or it was killed)"
            )
