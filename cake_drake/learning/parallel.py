"""Episodes spread over workers: here, on a pool of spawned processes, or on Ray."""

from __future__ import annotations

import multiprocessing


def imap(fn, jobs, workers: int, ray=None):
    """``fn(job)`` for every job, yielded as each finishes: here (one worker), on a pool
    of spawned processes, or on ``ray`` (a :class:`cake_drake.sweeps.RayCluster`)."""
    if ray is not None:
        yield from ray.imap(fn, jobs)
    elif workers <= 1 or len(jobs) <= 1:
        yield from (fn(j) for j in jobs)
    else:
        ctx = multiprocessing.get_context("spawn")
        with ctx.Pool(min(workers, len(jobs))) as pool:
            yield from pool.imap_unordered(fn, jobs, chunksize=1)


def map_ordered(fn, jobs, workers: int, ray=None) -> list:
    """:func:`imap`'s answers in the order of ``jobs`` (each answer has its ``seed``)."""
    answers = list(imap(fn, jobs, workers, ray))
    order = {job[1]: k for k, job in enumerate(jobs)}
    return sorted(answers, key=lambda a: order[a["seed"]])
