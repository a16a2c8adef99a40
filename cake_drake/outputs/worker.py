"""Helper processes for the slow outputs, so they overlap the simulation.

Building a VTK world and importing matplotlib together take about half as long as
simulating the whole task. Two helpers are forked at the start of a run, one for the
picture and one for the plot: while the main process plans and simulates, the first
builds its :class:`Renderer` and renders once (the meshes load then), then the second
imports the plotting code and prepares the plot's figure (one at a time, so that on two
cores the simulation always has one to itself). At the end they get the final state and
the logs and write ``final_state.png`` and the joint plot side by side, while the main
process writes the rest. Apart, each stays small (VTK and matplotlib never share a
process). Helpers are forked only when a core is free for them (:func:`spare_core`): on
a busy machine they would only compete with the simulation for the cores. Without them,
where forking is not available, or when a helper fails, the same functions run in-process;
so does the picture after this process made a render engine (whose GL state a fork
cannot carry).
"""

from __future__ import annotations

import multiprocessing as mp
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix


def _pack(poses: Mapping[str, RigidTransform]) -> dict[str, np.ndarray]:
    return {n: X.GetAsMatrix4() for n, X in poses.items()}


def _unpack(packed: Mapping[str, np.ndarray]) -> dict[str, RigidTransform]:
    return {n: RigidTransform(RotationMatrix(M[:3, :3]), M[:3, 3]) for n, M in packed.items()}


def render_png(blocks, poses, q_arm, fingers, path, renderer=None) -> None:
    from cake_drake.world.render import Renderer, save_png

    renderer = renderer or Renderer(blocks)
    save_png(renderer.render(poses, q_arm, fingers), path)


def plot_png(job: dict, figure=None) -> None:
    """Draw one plot job: the run's cake (a job with ``layers``) or the joint plot."""
    if "layers" in job:
        from cake_drake.outputs.cake import write_cake

        write_cake(**job)
        return
    from cake_drake.outputs.plots import joint_plot

    joint_plot(**job, figure=figure)


def _warm_picture(blocks, warm_poses):
    """Build the renderer and render once; returns the job handler."""
    from cake_drake.world.render import Renderer

    renderer = Renderer(blocks)
    renderer.render(_unpack(warm_poses))

    def handle(args) -> None:
        poses, q_arm, fingers, path = args
        render_png(blocks, _unpack(poses), q_arm, fingers, path, renderer)

    return handle


def _warm_plot():
    """Import the plotting code (matplotlib) now, not at the end, and prepare the joint
    plot's figure (drawn once, empty: see :func:`cake_drake.outputs.plots.joint_figure`);
    returns the job handler."""
    from cake_drake.outputs.plots import joint_figure

    ready = [joint_figure(drawn=True)]  # for joint 4, the one a run plots

    def handle(job: dict) -> None:
        joint_job = "layers" not in job and job.get("joint", 4) == 4
        figure = ready.pop() if ready and joint_job else None
        plot_png(job, figure)

    return handle


def _serve(conn, parent_end, warm, args, what: str, after, warmed) -> None:
    import signal

    # The fork copied the parent's end of the pipe too: close it, so that the parent's
    # death (a crash, a kill) is an end of file here and this process ends with it.
    parent_end.close()
    # Ctrl-C reaches the whole process group: the parent decides, the helper stays quiet.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if after is not None:
        after.wait(WARM_WAIT_S)
    try:
        try:
            handle = warm(*args)
        except Exception as e:  # noqa: BLE001 - reported to the parent as one line
            conn.send(("error", f"output worker failed to start: {e}"))
            return
        finally:
            if warmed is not None:
                warmed.set()
        while True:
            job = conn.recv()
            if job is None:
                return
            try:
                handle(job)
                conn.send(("ok", what))
            except Exception as e:  # noqa: BLE001
                conn.send(("error", f"writing the {what} output failed: {e}"))
    except (EOFError, OSError):  # the parent is gone (stopped, killed): nothing to tell
        return


#: How long (s) the plot's helper waits for the picture's to warm up before it starts anyway.
WARM_WAIT_S = 10.0


class _Helper:
    """One forked helper process and its pipe."""

    def __init__(self, warm, args, what: str, after=None, warmed=None) -> None:
        """``after``: an event to wait for before warming up; ``warmed``: one to set after."""
        self.what = what
        self.pending = 0
        ctx = mp.get_context("fork")
        self.conn, child = ctx.Pipe()
        self.process = ctx.Process(
            target=_serve, args=(child, self.conn, warm, args, what, after, warmed), daemon=True
        )
        self.process.start()
        child.close()  # the helper's end lives in the helper alone

    def submit(self, job) -> None:
        self.pending += 1
        try:
            self.conn.send(job)
        except OSError:  # the helper is gone: wait() says so
            pass

    def wait(self, deadline: float, timeout_s: float) -> str | None:
        """Wait for every submitted job; the first error, if any (RuntimeError when the
        helper died or did not answer by ``deadline``)."""
        import time

        error = None
        while self.pending:
            if not self.conn.poll(0.2):
                if not self.process.is_alive():
                    raise self._stopped()
                if time.monotonic() > deadline:
                    raise RuntimeError(f"the output helper did not answer in {timeout_s:g} s")
                continue
            try:
                status, detail = self.conn.recv()
            except EOFError:
                raise self._stopped() from None
            if status == "error":
                error = error or detail
                if "failed to start" in detail:
                    break
            self.pending -= 1
        return error

    def _stopped(self) -> RuntimeError:
        self.process.join(1.0)
        return RuntimeError(
            f"the output helper stopped (exit code {self.process.exitcode}) "
            f"before writing the {self.what}"
        )

    def close(self) -> None:
        if self.process.is_alive():
            try:
                self.conn.send(None)
            except OSError:
                pass
            self.process.join(timeout=5)
            if self.process.is_alive():
                self.process.terminate()


def _runnable() -> int:
    """Tasks ready to run on the machine now, this one included (Linux's /proc/loadavg)."""
    with open("/proc/loadavg") as f:
        return int(f.read().split()[3].split("/")[0])


def spare_core(samples: int = 8, gap_s: float = 0.0005) -> bool:
    """Whether a core is free for the helpers besides this process's own: over a few
    milliseconds, the fewest tasks ready to run (this process included) stays below the
    cores this process may use. Where that cannot be read: assumed free.

    On a busy machine, helpers compete with the simulation for the cores instead of
    using an idle one: measured on two cores with a second run looping beside it, a run
    that draws its outputs itself after the simulation took 2.95 s against 3.13 s with
    helpers (quiet, helpers win: 2.36 s against 2.92 s; see docs/speed.md)."""
    import os
    import time

    try:
        cores = len(os.sched_getaffinity(0))
        fewest = _runnable()
        for _ in range(samples - 1):
            time.sleep(gap_s)
            fewest = min(fewest, _runnable())
    except (OSError, ValueError, IndexError, AttributeError):
        return True
    return fewest < cores


def _gl_here() -> bool:
    """Whether this process made a render engine (a notebook, a suite, a run with
    cameras): a picture helper forked now would inherit its GL state and hang at its
    first render, so the picture is drawn in this process instead (the plot's helper,
    which renders nothing, is forked as before)."""
    import sys

    cameras = sys.modules.get("cake_drake.world.cameras")
    return bool(cameras is not None and cameras.engines_made)


class OutputWorker:
    """Fork the helpers now, with the blocks and initial poses; hand over the picture and
    the plot later. ``helpers`` is ``outputs.helpers`` (auto, always or never); with
    ``auto``, they are forked only when :func:`spare_core` finds a core free. Without
    them the picture and the plot are drawn in this process when they are asked for."""

    def __init__(
        self,
        blocks: Sequence[str],
        initial_poses: Mapping[str, RigidTransform],
        render: bool,
        helpers: str = "auto",
    ):
        self._blocks = list(blocks)
        self._picture = self._plot = None
        self.forked = spare_core() if helpers == "auto" else helpers == "always"
        if not self.forked:
            return
        # After a render engine was made here, the picture is drawn in this process.
        render = render and not _gl_here()
        try:
            # One helper warms up at a time, so the simulation keeps a core to itself.
            warmed = mp.get_context("fork").Event() if render else None
            if render:
                args = (self._blocks, _pack(initial_poses))
                self._picture = _Helper(_warm_picture, args, "picture", warmed=warmed)
            self._plot = _Helper(_warm_plot, (), "plot", after=warmed)
        except (ValueError, OSError):
            self.close()
            self._picture = self._plot = None

    def submit_render(self, poses, q_arm: np.ndarray, fingers: float, path: Path) -> None:
        """Start writing the picture of the given state to ``path``."""
        if self._picture is None:
            render_png(self._blocks, poses, q_arm, fingers, path)
            return
        self._picture.submit((_pack(poses), np.asarray(q_arm), float(fingers), Path(path)))

    def submit_plot(self, **job) -> None:
        """Start :func:`cake_drake.outputs.plots.joint_plot` with these arguments, or
        :func:`cake_drake.outputs.cake.write_cake` for a job with ``layers``."""
        if self._plot is None:
            plot_png(job)
            return
        self._plot.submit(job)

    def submit_cake(self, layers: dict, title: str) -> None:
        """Start drawing the run's cake (:func:`cake_drake.outputs.cake.write_cake`) now,
        while the world is simulated: the layers are known once the plan is. It is drawn
        into a private folder; :meth:`cake` gives the file once :meth:`wait` returned.
        Asked for once: a second call draws nothing (the folder is removed by
        :meth:`close`)."""
        import tempfile

        if self.cake_asked:
            return
        self._cake_dir = Path(tempfile.mkdtemp(prefix="cake_drake-cake-"))
        self.submit_plot(layers=layers, path=self._cake_dir / "cake.png", title=title)

    @property
    def cake_asked(self) -> bool:
        """Whether :meth:`submit_cake` was called (the cake may still be being drawn)."""
        return getattr(self, "_cake_dir", None) is not None

    def cake(self) -> Path | None:
        """The cake drawn by :meth:`submit_cake`, if it was asked for and is there."""
        folder = getattr(self, "_cake_dir", None)
        path = folder / "cake.png" if folder is not None else None
        return path if path is not None and path.is_file() else None

    def wait(self, timeout_s: float = 120.0) -> None:
        """Wait for every submitted job; raises RuntimeError naming the first that failed,
        or saying that a helper died or did not answer within ``timeout_s``."""
        import time

        deadline = time.monotonic() + timeout_s
        errors = [h.wait(deadline, timeout_s) for h in (self._picture, self._plot) if h]
        errors = [e for e in errors if e]
        if errors:
            raise RuntimeError(errors[0])

    def close(self) -> None:
        for helper in (self._picture, self._plot):
            if helper is not None:
                helper.close()
        folder = getattr(self, "_cake_dir", None)
        if folder is not None:
            import shutil

            shutil.rmtree(folder, ignore_errors=True)
