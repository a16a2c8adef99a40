"""Episodes spread over workers: here, on a local pool of spawned processes, or on Ray.

The local pool is the sweeps' (:func:`cake_drake.sweeps.pool.spawn_imap`): whatever stops
it (the last episode, an error, Ctrl-C or SIGTERM), its workers are told, joined with a
deadline, then killed. A worker's :class:`~cake_drake.errors.CakeDrakeError` (a policy
plug-in that failed, bad input) comes back as itself: its one line and its exit code.

A worker shares the cores: a policy that runs on torch (a checkpoint's network) gets its
share of them as threads, not every core each, which on a busy machine made one answer
several times slower.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass

from cake_drake.errors import CakeDrakeError


@dataclass
class _Failed:
    """A worker's CakeDrakeError, carried back as data (its class's own pickling would
    lose the exit code)."""

    message: str
    exit_code: int
    trace: str | None


def limit_threads(threads: int) -> None:
    """Give torch ``threads`` threads in this process, whether it is imported yet or not."""
    os.environ["OMP_NUM_THREADS"] = str(threads)  # read when torch is first imported
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(threads)


def _guarded_call(pair):
    """``fn(job)`` for ``pair = (fn, job, threads)``, in a worker (a module-level function,
    which spawned processes and Ray both take by name)."""
    fn, job, threads = pair
    limit_threads(threads)
    try:
        return fn(job)
    except CakeDrakeError as e:
        return _Failed(str(e), e.exit_code, getattr(e, "trace", None))


def _raise(answer):
    if isinstance(answer, _Failed):
        error = CakeDrakeError(answer.message)
        error.exit_code, error.trace = answer.exit_code, answer.trace
        raise error
    return answer


def imap(fn, jobs, workers: int, ray=None):
    """``fn(job)`` for every job, yielded as each finishes: here (one worker), on a pool
    of spawned processes, or on ``ray`` (a :class:`cake_drake.sweeps.RayCluster`)."""
    if ray is not None:  # a task a core
        yield from (_raise(a) for a in ray.imap(_guarded_call, [(fn, j, 1) for j in jobs]))
    elif workers <= 1 or len(jobs) <= 1:
        yield from (fn(j) for j in jobs)
    else:
        # Loaded here, not at import: the sweeps package draws its tables with matplotlib
        # (about 0.5 s), which a process that evaluates or records in-process never needs.
        from cake_drake.sweeps.pool import spawn_imap

        workers = min(workers, len(jobs))
        threads = max(1, len(os.sched_getaffinity(0)) // workers)
        answers = spawn_imap(_guarded_call, [(fn, j, threads) for j in jobs], workers)
        try:
            yield from (_raise(a) for a in answers)
        finally:  # an error, or a caller that stops early: the workers end now, not at exit
            answers.close()


def map_ordered(fn, jobs, workers: int, ray=None) -> list:
    """:func:`imap`'s answers in the order of ``jobs`` (each answer has its ``seed``)."""
    answers = list(imap(fn, jobs, workers, ray))
    order = {job[1]: k for k, job in enumerate(jobs)}
    return sorted(answers, key=lambda a: order[a["seed"]])
