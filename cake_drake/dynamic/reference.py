"""Reference trajectories for the controllers: replaying a recorded ``trajectory.npz``.

The exercise's computed-torque drill drives the arm from the positions recorded in the
position run; velocity and acceleration have to be recovered. ``spline`` fits a cubic
with continuous second derivative through the samples (zero velocity at both ends) and
differentiates it; ``central`` takes central differences of the samples, once and
twice. :meth:`ReferenceTrajectory.make_source` serves it with Drake's
``TrajectorySource`` behind the same named ports ``WaypointIk`` has, so the controller
and the loggers cannot tell a replay from a planned run.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import Demultiplexer, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from cake_drake.errors import InputError
from cake_drake.formats import load_npz

#: Sizes of the named output ports every reference source has (``WaypointIk``, a learned
#: skill and the recorded replay alike): what the controller below follows.
REFERENCE_PORTS = {
    "desired_state": 14,  # q_d (7), v_d (7)
    "desired_acceleration": 7,  # a_d
    "finger_state": 4,  # desired finger state: q1, q2, v1, v2
    "actions_done": 1,
    "labels": 2,  # phase index, action index (-1 when idle)
}

DIFFERENTIATORS = ("spline", "central")


def _check_labels(path, n: int, gripper, phase, action, actions) -> None:
    """Refuse label and gripper arrays a replay could not follow, naming the array."""
    from cake_drake.formats import PHASE_NAMES

    where = f"{path}: array"
    for name, a in (("gripper", gripper), ("phase", phase), ("action", action)):
        if a.shape != (n,) or a.dtype.kind not in "iuf":
            raise InputError(f"{where} {name!r} must hold {n} numbers, one per time")
        if not np.all(np.isfinite(a)):
            raise InputError(f"{where} {name!r} must be finite")
    if np.any(gripper < 0) or np.any(gripper > 0.04):
        raise InputError(f"{where} 'gripper' must be finger openings from 0 to 0.04 m")
    if np.any(phase != np.round(phase)) or phase.min() < 0 or phase.max() >= len(PHASE_NAMES):
        raise InputError(
            f"{where} 'phase' must be whole numbers from 0 to {len(PHASE_NAMES) - 1} "
            f"({', '.join(PHASE_NAMES)})"
        )
    top = len(actions) - 1 if actions else None
    if (
        np.any(action != np.round(action))
        or action.min() < -1
        or (top is not None and action.max() > top)
    ):
        bound = f"{top}" if top is not None else "the number of actions - 1"
        raise InputError(f"{where} 'action' must be whole numbers from -1 (idle) to {bound}")


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
        actions = tuple(str(s) for s in data.get("actions", ()))
        _check_labels(path, n, data["gripper"], phase, action, actions)
        return cls(
            t,
            q,
            qd,
            qdd,
            data["gripper"].astype(float),
            phase,
            action,
            tuple(str(s) for s in data.get("phases", ())),
            actions,
        )

    def executed_actions(self) -> tuple[str, ...]:
        """The actions the recording carries out (those with samples), in order."""
        indices = sorted({int(k) for k in self.action if k >= 0})
        return tuple(
            self.actions[k] if k < len(self.actions) else f"action {k + 1}" for k in indices
        )

    def actions_done(self) -> np.ndarray:
        """At each sample, how many actions have ended (their last sample is behind)."""
        last = {}
        for i, k in enumerate(self.action):
            if k >= 0:
                last[int(k)] = i
        ends = np.sort(np.array(list(last.values()), dtype=int))
        return np.searchsorted(ends, np.arange(len(self.t)), side="right").astype(float)

    def matrix(self) -> np.ndarray:
        """The rows of every named port, stacked: q, v, a, finger state, done, phase, action."""
        g = self.gripper.reshape(len(self.t))
        return np.vstack(
            [
                self.q.T,
                self.qd.T,
                self.qdd.T,
                g,
                g,
                np.zeros_like(g),
                np.zeros_like(g),
                self.actions_done(),
                self.phase.astype(float),
                self.action.astype(float),
            ]
        )

    def make_source(self) -> Diagram:
        """``TrajectorySource`` over a first-order hold, exported as the named ports
        ``desired_state``, ``desired_acceleration``, ``finger_state``, ``actions_done`` and
        ``labels`` (the ones ``WaypointIk`` has)."""
        builder = DiagramBuilder()
        traj = PiecewisePolynomial.FirstOrderHold(self.t, self.matrix())
        source = builder.AddNamedSystem("trajectory", TrajectorySource(traj, 0, True))
        split = builder.AddNamedSystem("split", Demultiplexer(list(REFERENCE_PORTS.values())))
        builder.Connect(source.get_output_port(), split.get_input_port())
        for i, name in enumerate(REFERENCE_PORTS):
            builder.ExportOutput(split.get_output_port(i), name)
        diagram = builder.Build()
        diagram.set_name("recorded_reference")
        return diagram
