"""Where the runs of a sweep execute: a local process pool, or Ray (one machine or many).

Both take the same jobs and give the same events; both run
:func:`cake_drake.sweeps.worker.execute`. An engine yields ``("start", job)`` when a run
is handed to a worker and ``("done", job, answer)`` with the worker's answer (or a
crashed row when the worker died). The engines submit no more runs than they have
workers, so "running" means running. The local pool is
:mod:`cake_drake.sweeps.pool`, whose :func:`~cake_drake.sweeps.pool.spawn_imap` runs any
work the same way.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import signal
import socket
import tempfile
import threading
import time
from collections import deque
from collections.abc import Iterator, Sequence

from cake_drake.errors import InputError
from cake_drake.sweeps.pool import spawn_events
from cake_drake.sweeps.worker import crashed_row, execute

Event = tuple
CRASHED = "the worker process died while running this run (a crash, or it was killed)"


class LocalPool:
    """A pool of spawned worker processes on this machine (default: one per core), on
    :func:`cake_drake.sweeps.pool.spawn_events`: a run whose worker dies is a crashed row
    (that worker alone is replaced; the runs beside it go on), and whatever stops the
    sweep, the workers are gone within a deadline."""

    name = "local pool"

    def __init__(self, workers: int | None = None) -> None:
        if workers is not None and workers < 1:
            raise InputError(f"--workers {workers}: give one or more")
        self.workers = workers or os.cpu_count() or 1

    def __str__(self) -> str:
        return f"local pool of {self.workers} worker{'s' * (self.workers != 1)}"

    def events(self, jobs: Sequence[dict]) -> Iterator[Event]:
        events = spawn_events(execute, jobs, self.workers)
        try:
            for event in events:
                kind, job = event[0], event[1]
                if kind == "died":
                    yield ("done", job, {"row": crashed_row(job, CRASHED), "files": {}})
                elif kind == "error":  # execute answers every run: this is the worker's end
                    why = f"{CRASHED}: {event[2]}"
                    yield ("done", job, {"row": crashed_row(job, why), "files": {}})
                else:
                    yield event
        finally:
            events.close()  # the workers gone, within a deadline, however this ends


#: What Ray adds to its folder for its longest socket's path, which Linux bounds.
_RAY_SOCKET_TAIL = len("/session_2026-12-02_05-48-20_304566_4194304/sockets/plasma_store")
_SOCKET_PATH_MAX = 107


def _session_folder() -> str:
    """A new folder for a local Ray instance's session: in the temporary folder, or in
    /tmp where that one's path is too long for Ray's sockets."""
    folder = tempfile.mkdtemp(prefix="cake_drake_ray_")
    if len(os.fsencode(folder)) + _RAY_SOCKET_TAIL > _SOCKET_PATH_MAX:
        os.rmdir(folder)
        folder = tempfile.mkdtemp(prefix="cake_drake_ray_", dir="/tmp")
    return folder


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
        self._folder: str | None = None
        if importlib.util.find_spec("ray") is None:
            raise InputError("--ray needs Ray: pip install 'cake_drake[ray]' (or pip install ray)")
        self._reachable()  # before the sweep writes anything

    def __str__(self) -> str:
        return f"Ray cluster at {self.address}" if self.address else "local Ray instance"

    def _init(self):
        import ray

        if not ray.is_initialized():
            kwargs = dict(include_dashboard=False, log_to_driver=False, logging_level="ERROR")
            # Ray puts its own handlers on SIGINT and SIGTERM (a crash dump and an abort
            # 3 s after SIGTERM): the command's are put back, so a stop is one line and 130.
            handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
            alarm = signal.getsignal(signal.SIGALRM)
            try:
                if self.address:
                    ray.init(address=self.address, **kwargs)
                else:  # its session folder (logs, sockets) in one of ours, removed at stop
                    self._folder = _session_folder()
                    ray.init(num_cpus=self.num_cpus, _temp_dir=self._folder, **kwargs)
            except (ConnectionError, ValueError, RuntimeError) as e:
                self._remove_folder()
                where = self.address or "a local instance"
                first = (str(e).strip().splitlines() or [type(e).__name__])[0]
                raise InputError(f"--ray {where}: cannot start or join Ray ({first})") from None
            except BaseException as e:  # an interrupt while it starts
                # A SIGTERM in there met Ray's handlers: its C++ one armed an abort 3 s on
                # (the real-time timer, SIGALRM) and its Python one raised SystemExit(15).
                signal.setitimer(signal.ITIMER_REAL, 0)
                ray.shutdown()
                self._remove_folder()
                ours = handlers.get(signal.SIGTERM)
                if isinstance(e, SystemExit) and e.code == signal.SIGTERM and callable(ours):
                    ours(signal.SIGTERM, None)  # the command's own: stopped by SIGTERM, 130
                raise
            finally:
                if threading.current_thread() is threading.main_thread():
                    for s, handler in (*handlers.items(), (signal.SIGALRM, alarm)):
                        signal.signal(s, handler)
            self._started = True
        return ray

    def _remove_folder(self) -> None:
        """Remove the session folder; Ray's processes, stopping, may still write in it for
        a moment, so it is removed again until it stays gone (at most 2 s)."""
        if self._folder is not None:
            for _ in range(20):
                shutil.rmtree(self._folder, ignore_errors=True)
                if not os.path.exists(self._folder):
                    break
                time.sleep(0.1)
            self._folder = None

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

    def start(self):
        """Start or join Ray now, before anything is written; the ``ray`` module, ready."""
        return self._init()

    def stop(self) -> None:
        """Shut down the instance :meth:`start` began here (a cluster joined is left up)."""
        if self._started:
            import ray

            ray.shutdown()
            self._started = False
            self._remove_folder()

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
            self.stop()

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
            self.stop()
