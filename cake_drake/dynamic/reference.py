"""Reference trajectories for the controllers: replaying a recorded ``trajectory.npz``.

The exercise's computed-torque drill drives the arm from the positions recorded in the
position run; velocity and acceleration have to be recovered. ``spline`` fits a cubic
with continuous second derivative through the samples (zero velocity at both ends) and
differentiates it; ``central`` takes central differences of the samples, once and
twice. The result is the same 28-vector ``WaypointIk`` emits, served by Drake's
``TrajectorySource``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.systems.primitives import TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from cake_drake.errors import InputError
from cake_drake.geometric.trajectory import load_npz

DIFFERENTIATORS = ("spline", "central")


@dataclass
class ReferenceTrajectory:
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    gripper: np.ndarray
    phase: np.ndarray
    action: np.ndarray
    phases: tuple[str, ...]
    actions: tuple[str, ...]

    @property
    def end_time(self) -> float:
        return float(self.t[-1])

    @classmethod
    def from_npz(cls, path: str | Path, differentiate: str = "spline") -> ReferenceTrajectory:
        if differentiate not in DIFFERENTIATORS:
            raise InputError(
                f"unknown differentiation {differentiate!r}; choose one of: "
                f"{', '.join(DIFFERENTIATORS)}"
            )
        data = load_npz(path)
        t, q = data["t"].astype(float), data["q"].astype(float)
        if differentiate == "spline":
            spline = PiecewisePolynomial.CubicWithContinuousSecondDerivatives(
                t, q.T, np.zeros(7), np.zeros(7)
            )
            qd = np.array([spline.EvalDerivative(ti, 1) for ti in t])[:, :, 0]
            qdd = np.array([spline.EvalDerivative(ti, 2) for ti in t])[:, :, 0]
        else:
            qd = np.gradient(q, t, axis=0)
            qdd = np.gradient(qd, t, axis=0)
        n = len(t)
        phase = data.get("phase", np.zeros(n, int))
        action = data.get("action", -np.ones(n, int))
        return cls(
            t,
            q,
            qd,
            qdd,
            data["gripper"].astype(float),
            phase,
            action,
            tuple(str(s) for s in data.get("phases", ())),
            tuple(str(s) for s in data.get("actions", ())),
        )

    def matrix(self) -> np.ndarray:
        """The 28 x N reference: q, v, a, finger state, done (0), phase, action."""
        n = len(self.t)
        g = self.gripper.reshape(n)
        return np.vstack(
            [
                self.q.T,
                self.qd.T,
                self.qdd.T,
                g,
                g,
                np.zeros(n),
                np.zeros(n),
                np.zeros(n),
                self.phase.astype(float),
                self.action.astype(float),
            ]
        )

    def make_source(self) -> TrajectorySource:
        """Drake's ``TrajectorySource`` over a first-order hold of :meth:`matrix`."""
        traj = PiecewisePolynomial.FirstOrderHold(self.t, self.matrix())
        return TrajectorySource(traj, 0, True)
