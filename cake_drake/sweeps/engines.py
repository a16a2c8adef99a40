"""Where the runs of a sweep execute: a local process pool, or Ray (one machine or many).

Both take the same jobs and give the same events; both run
:func:`cake_drake.sweeps.worker.execute`. An engine yields ``("start", job)`` when a run
is handed to a worker, ``("queued", job)`` when it goes back to waiting, and
``("done", job, answer)`` with the worker's answer (or a crashed row when the worker
died). The engines submit no more runs than they have workers, so "running" means
running.
"""

from __future__ import annotations

import importlib.util
import multiprocessing
import os
import signal
import socket
from collections import deque
from collections.abc import Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool

from cake_drake.errors import InputError
from cake_drake.sweeps.worker import crashed_row, execute

Event = tuple
CRASHED = "the worker process died while running this run (a crash, or it was killed)"


def _quiet_worker(parent: int | None = None) -> None:
    """Workers leave Ctrl-C to the sweep, which stops them itself, and end with it: on
    Linux the kernel kills a worker whose sweep is gone (even by SIGKILL), and a worker
    whose sweep was already gone when it started ends at once."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        import ctypes

        PR_SET_PDEATHSIG = 1
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):  # not Linux: the pool's own pipes end it later
        pass
    if parent is not None and os.getppid() != parent:
        os._exit(1)


def _stop(pool: ProcessPoolExecutor) -> None:
    """Stop a pool now: running workers are terminated, queued calls dropped."""
    terminate = getattr(pool, "terminate_workers", None)  # Python >= 3.14
    if terminate is not None:
        terminate()
        return
    for process in list((getattr(pool, "_processes", None) or {}).values()):
        process.terminate()
    pool.shutdown(wait=False, cancel_futures=True)


class LocalPool:
    """A pool of spawned worker processes on this machine (default: one per core).

    A worker that dies takes the pool down with it, and every run in flight with it;
    those runs are then tried again one at a time, alone, so that only the run that
    kills its worker becomes a crashed row.
    """

    name = "local pool"

    def __init__(self, workers: int | None = None) -> None:
        if workers is not None and workers < 1:
            raise InputError(f"--workers {workers}: give one or more")
        self.workers = workers or os.cpu_count() or 1

    def __str__(self) -> str:
        return f"local pool of {self.workers} worker{'s' * (self.workers != 1)}"

    def events(self, jobs: Sequence[dict]) -> Iterator[Event]:
        queue = deque(jobs)
        while queue:
            suspects = yield from self._batch(queue, self.workers)
            for job in suspects:  # alone, so a crash names its own run
                yield ("start", job)
                alone = deque([job])
                again = yield from self._batch(alone, 1)
                if again:
                    yield ("done", job, {"row": crashed_row(job, CRASHED), "files": {}})

    def _batch(self, queue: deque, workers: int) -> Iterator[Event]:
        """Run from ``queue`` on a fresh pool until it is empty (return []) or a worker
        dies (return the runs that were in flight, for the caller to retry)."""
        context = multiprocessing.get_context("spawn")
        pool = ProcessPoolExecutor(
            workers, mp_context=context, initializer=_quiet_worker, initargs=(os.getpid(),)
        )
        running: dict = {}

        def refill():
            while queue and len(running) < workers:
                job = queue.popleft()
                running[pool.submit(execute, job)] = job
                yield ("start", job)

        try:
            while queue or running:
                yield from refill()
                finished, _ = wait(running, return_when=FIRST_COMPLETED)
                broken = False
                answers = []
                for future in finished:
                    try:
                        answers.append((running[future], future.result()))
                        del running[future]
                    except BrokenProcessPool:
                        broken = True
                if not broken:
                    yield from refill()  # the next runs start before the answers are kept
                for job, answer in answers:
                    yield ("done", job, answer)
                if broken:
                    suspects = list(running.values())
                    for job in suspects:
                        yield ("queued", job)
                    return suspects
            return []
        except BaseException:
            _stop(pool)
            raise
        finally:
            pool.shutdown(wait=False, cancel_futures=True)


class RayCluster:
    """Ray: a local instance started here (``address=None``), or a cluster joined at
    ``address`` (``auto`` for the cluster this machine belongs to, or ``HOST:PORT``).

    Every node needs the same cake_drake installed; each run's files come back to
    this machine with its row, so no shared file system is needed.
    """

    name = "ray"

    def __init__(self, address: str | None = None, num_cpus: int | None = None) -> None:
        self.address = address
        self.num_cpus = num_cpus
        self._started = False
        if importlib.util.find_spec("ray") is None:
            raise InputError("--ray needs Ray: pip install 'cake_drake[ray]' (or pip install ray)")
        self._reachable()  # before the sweep writes anything

    def __str__(self) -> str:
        return f"Ray cluster at {self.address}" if self.address else "local Ray instance"

    def _init(self):
        import ray

        if not ray.is_initialized():
            kwargs = dict(include_dashboard=False, log_to_driver=False, logging_level="ERROR")
            try:
                if self.address:
                    ray.init(address=self.address, **kwargs)
                else:
                    ray.init(num_cpus=self.num_cpus, **kwargs)
            except (ConnectionError, ValueError, RuntimeError) as e:
                where = self.address or "a local instance"
                first = (str(e).strip().splitlines() or [type(e).__name__])[0]
                raise InputError(f"--ray {where}: cannot start or join Ray ({first})") from None
            self._started = True
        return ray

    def _reachable(self) -> None:
        """Refuse an address nothing answers at (Ray itself would retry for minutes)."""
        if not self.address or self.address == "auto":
            return
        host, _, port = self.address.split("://")[-1].rpartition(":")
        try:
            socket.create_connection((host or "localhost", int(port)), timeout=5).close()
        except (OSError, ValueError):
            raise InputError(
                f"--ray {self.address}: no Ray cluster answers there (give HOST:PORT of a "
                "head started with `ray start --head`, or auto on one of its nodes)"
            ) from None

    def start(self) -> None:
        """Start or join Ray now, before the sweep writes anything."""
        self._init()

    def imap(self, fn, items: Sequence) -> Iterator:
        """``fn(item)`` for every item, each on a Ray worker (one CPU each), yielded as
        they finish (for work that is not a sweep's runs: episodes)."""
        ray = self._init()
        remote = ray.remote(num_cpus=1, max_retries=0)(fn)
        running = [remote.remote(item) for item in items]
        try:
            while running:
                ready, running = ray.wait(running, num_returns=1)
                yield ray.get(ready[0])
        except BaseException:
            for ref in running:
                ray.cancel(ref, force=True)
            raise
        finally:
            if self._started:
                ray.shutdown()
                self._started = False

    def events(self, jobs: Sequence[dict]) -> Iterator[Event]:
        ray = self._init()
        remote = ray.remote(num_cpus=1, max_retries=0)(execute)
        queue = deque(jobs)
        running: dict = {}

        def refill():
            slots = max(1, int(ray.cluster_resources().get("CPU", 1)))
            while queue and len(running) < slots:
                job = queue.popleft()
                running[remote.remote(job)] = job
                yield ("start", job)

        try:
            while queue or running:
                yield from refill()
                ready, _ = ray.wait(list(running), num_returns=1)
                jobs_ready = [(ref, running.pop(ref)) for ref in ready]
                yield from refill()  # the next runs start before the answers are kept
                for ref, job in jobs_ready:
                    try:
                        answer = ray.get(ref)
                    except ray.exceptions.RayError as e:
                        first = (str(e).strip().splitlines() or [type(e).__name__])[0]
                        answer = {"row": crashed_row(job, f"{CRASHED}: {first}"), "files": {}}
                    yield ("done", job, answer)
        except BaseException:
            for ref in running:
                ray.cancel(ref, force=True)
            raise
        finally:
            if self._started:
                ray.shutdown()
                self._started = False
