"""A second process for the slow outputs, so they overlap the simulation.

Loading the Panda's visual meshes into VTK and importing matplotlib together take
about as long as simulating the whole task. The worker is forked at the start of a
run; while the main process plans and simulates it builds its :class:`Renderer`,
renders once (the meshes load then) and imports the plotting code. At the end it gets
the final state and the logs, and writes ``final_state.png`` and the joint plot while
the main process writes the rest. Where forking is not available, or the worker
fails, the same functions run in-process.
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


def plot_png(job: dict) -> None:
    from cake_drake.outputs.plots import joint_plot

    joint_plot(**job)


def _serve(conn, parent_end, blocks, warm_poses, render: bool) -> None:
    import signal

    # The fork copied the parent's end of the pipe too: close it, so that the parent's
    # death (a crash, a kill) is an end of file here and this process ends with it.
    parent_end.close()
    # Ctrl-C reaches the whole process group: the parent decides, the helper stays quiet.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    renderer = None
    try:
        if render:
            from cake_drake.world.render import Renderer

            renderer = Renderer(blocks)
            renderer.render(_unpack(warm_poses))
        from cake_drake.outputs.plots import warm_up

        warm_up()  # matplotlib and its fonts load now, not at the end
    except Exception as e:  # noqa: BLE001 - reported to the parent as one line
        conn.send(("error", f"output worker failed to start: {e}"))
        return
    while True:
        try:
            job = conn.recv()
        except EOFError:
            return
        if job is None:
            return
        kind, args = job
        try:
            if kind == "render":
                poses, q_arm, fingers, path = args
                render_png(blocks, _unpack(poses), q_arm, fingers, path, renderer)
            else:
                plot_png(args)
            conn.send(("ok", kind))
        except Exception as e:  # noqa: BLE001
            conn.send(("error", f"writing the {kind} output failed: {e}"))


class OutputWorker:
    """Fork now with the blocks and initial poses; hand over render and plot jobs later."""

    def __init__(
        self, blocks: Sequence[str], initial_poses: Mapping[str, RigidTransform], render: bool
    ):
        self._blocks = list(blocks)
        self._render = render
        self._process = None
        self._pending = 0
        try:
            ctx = mp.get_context("fork")
            self._conn, child = ctx.Pipe()
            self._process = ctx.Process(
                target=_serve,
                args=(child, self._conn, self._blocks, _pack(initial_poses), render),
                daemon=True,
            )
            self._process.start()
            child.close()  # the helper's end lives in the helper alone
        except (ValueError, OSError):
            self._process = None

    def submit_render(self, poses, q_arm: np.ndarray, fingers: float, path: Path) -> None:
        """Start writing the picture of the given state to ``path``."""
        if self._process is None:
            render_png(self._blocks, poses, q_arm, fingers, path)
            return
        self._conn.send(("render", (_pack(poses), np.asarray(q_arm), float(fingers), Path(path))))
        self._pending += 1

    def submit_plot(self, **job) -> None:
        """Start :func:`cake_drake.outputs.plots.joint_plot` with these arguments."""
        if self._process is None:
            plot_png(job)
            return
        self._conn.send(("plot", job))
        self._pending += 1

    def wait(self, timeout_s: float = 120.0) -> None:
        """Wait for every submitted job; raises RuntimeError naming the first that failed,
        or saying that the helper died or did not answer within ``timeout_s``."""
        import time

        errors = []
        deadline = time.monotonic() + timeout_s
        while self._pending:
            if not self._conn.poll(0.2):
                if not self._process.is_alive():
                    raise RuntimeError(
                        f"the output helper stopped (exit code {self._process.exitcode}) "
                        "before writing the picture and the plot"
                    )
                if time.monotonic() > deadline:
                    raise RuntimeError(f"the output helper did not answer in {timeout_s:g} s")
                continue
            try:
                status, detail = self._conn.recv()
            except EOFError:
                raise RuntimeError("the output helper went away mid-job") from None
            if status == "error":
                errors.append(detail)
                if "failed to start" in detail:
                    break
                self._pending -= 1
            else:
                self._pending -= 1
        if errors:
            raise RuntimeError(errors[0])

    def close(self) -> None:
        if self._process is not None and self._process.is_alive():
            try:
                self._conn.send(None)
            except OSError:
                pass
            self._process.join(timeout=5)
            if self._process.is_alive():
                self._process.terminate()
