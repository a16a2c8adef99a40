"""An IK plug-in: Drake's solver, wrapped so that every query is kept.

A learned IK starts from data: the poses the pipeline asks for, the seeds it has, and
the answers a trusted solver gives. :class:`RecordingIk` answers with the shipped
:class:`~cake_drake.geometric.ik.DrakeIk` and keeps every ``(X_WG, q_seed, q)`` it saw;
:meth:`RecordingIk.save` writes them as arrays. Swap ``DrakeIk`` for a network and the
rest of the cake is unchanged.

Use it: ``motion: {ik: examples.recording_ik:make}`` or ``--ik examples.recording_ik:make``.
Every query is also written at once to ``ik_queries.npz`` in the working folder (replaced
whole after each solve), so a run from the command line leaves its data there.
"""

import os
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform

from cake_drake.geometric.ik import DrakeIk, Kinematics

#: The solvers made in this process, newest last (to read their records after a run).
MADE: list["RecordingIk"] = []
#: Where each solver keeps its queries (in the folder the run was started from).
FILE = Path("ik_queries.npz")


class RecordingIk:
    name = "recording-drake"

    def __init__(self, kinematics: Kinematics, seed: int) -> None:
        self._solver = DrakeIk(kinematics, seed=seed)
        self.poses: list[np.ndarray] = []  # 4x4 X_WG
        self.seeds: list[np.ndarray] = []
        self.answers: list[np.ndarray | None] = []

    def solve(self, X_WG: RigidTransform, q_seed: np.ndarray) -> np.ndarray | None:
        q = self._solver.solve(X_WG, q_seed)
        self.poses.append(X_WG.GetAsMatrix4())
        self.seeds.append(np.asarray(q_seed, float).copy())
        self.answers.append(None if q is None else np.asarray(q, float).copy())
        self.save(FILE)
        return q

    def save(self, path: str | Path) -> None:
        """``X_WG`` (N, 4, 4), ``q_seed`` (N, 7), ``q`` (N, 7; NaN where none), ``solved``;
        written to a temporary file and renamed, so ``path`` is always whole."""
        path = Path(path)
        solved = np.array([q is not None for q in self.answers])
        q = np.array([a if a is not None else np.full(7, np.nan) for a in self.answers])
        part = path.with_name(f".{path.name}.part")
        with open(part, "wb") as f:
            np.savez_compressed(
                f, X_WG=np.array(self.poses), q_seed=np.array(self.seeds), q=q, solved=solved
            )
        os.replace(part, path)


def make(kinematics: Kinematics, seed: int) -> RecordingIk:
    """The factory a scenario names."""
    solver = RecordingIk(kinematics, seed)
    MADE.append(solver)
    return solver
