"""Render the final state in a second process, so mesh loading overlaps the simulation.

Loading the Panda's visual meshes into VTK takes longer than simulating the whole task,
so the worker is forked at the start of a run, builds its :class:`Renderer` and renders
once (the meshes load then) while the main process plans and simulates; at the end it
gets the final state and writes the PNG. Where forking is not available it renders
in-process.
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


def _serve(conn, blocks, warm_poses) -> None:
    from cake_drake.world.render import Renderer, save_png

    try:
        renderer = Renderer(blocks)
        renderer.render(_unpack(warm_poses))
        conn.send(("ready", None))
    except Exception as e:  # noqa: BLE001 - reported to the parent as one line
        conn.send(("error", f"renderer failed to start: {e}"))
        return
    while True:
        request = conn.recv()
        if request is None:
            return
        poses, q_arm, fingers, path = request
        try:
            save_png(renderer.render(_unpack(poses), q_arm, fingers), path)
            conn.send(("ok", str(path)))
        except Exception as e:  # noqa: BLE001
            conn.send(("error", f"rendering {path} failed: {e}"))


class RenderWorker:
    """Start with the blocks and initial poses; :meth:`render` the final state later."""

    def __init__(self, blocks: Sequence[str], initial_poses: Mapping[str, RigidTransform]):
        self._blocks = list(blocks)
        self._initial = _pack(initial_poses)
        self._process = None
        try:
            ctx = mp.get_context("fork")
            self._conn, child = ctx.Pipe()
            self._process = ctx.Process(
                target=_serve, args=(child, self._blocks, self._initial), daemon=True
            )
            self._process.start()
        except (ValueError, OSError):
            self._process = None

    def render(
        self, poses: Mapping[str, RigidTransform], q_arm: np.ndarray, fingers: float, path: Path
    ) -> None:
        """Write the picture of the given state to ``path``; raises RuntimeError on failure."""
        if self._process is None:
            from cake_drake.world.render import Renderer, save_png

            save_png(Renderer(self._blocks).render(poses, q_arm, fingers), path)
            return
        status, detail = self._conn.recv()  # "ready" (or an error) from start-up
        if status == "error":
            raise RuntimeError(detail)
        self._conn.send((_pack(poses), np.asarray(q_arm), float(fingers), Path(path)))
        status, detail = self._conn.recv()
        if status == "error":
            raise RuntimeError(detail)

    def close(self) -> None:
        if self._process is not None and self._process.is_alive():
            try:
                self._conn.send(None)
            except OSError:
                pass
            self._process.join(timeout=5)
            if self._process.is_alive():
                self._process.terminate()
