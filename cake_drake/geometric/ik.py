"""Inverse kinematics behind one small interface, so a learned solver can drop in later.

An :class:`IkSolver` maps a desired grasp-frame pose ``X_WG`` and a seed configuration to
7 arm joint angles, or ``None``. Two solvers ship:

* :class:`DrakeIk` - Drake's ``InverseKinematics`` (position and orientation constraints,
  joint limits, a cost to stay near the seed), solved by Drake's default solver (SNOPT),
  retried from further seeds, every answer checked against forward kinematics. A few
  Gauss-Newton steps go first from the seed: they solve nearly every tabletop pose in
  well under a millisecond, and ``InverseKinematics`` handles what they cannot.
* :class:`DlsIk` - the exercise's damped least squares (damping 0.05, at most 200
  iterations) on Drake's Jacobian.

Both work on the 7-DOF control plant (:func:`cake_drake.world.scene.make_control_plant`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.solvers import Solve

from cake_drake.world.scene import Q_HOME, make_control_plant

#: Tolerances every solution is checked against, whatever the solver.
POSITION_TOL = 1e-4  # m
ORIENTATION_TOL = 1e-3  # rad


class IkSolver(Protocol):
    """What the geometric layer needs from an IK solver."""

    name: str

    def solve(self, X_WG: RigidTransform, q_seed: np.ndarray) -> np.ndarray | None:
        """Joint angles putting the grasp frame at ``X_WG``, near ``q_seed``; ``None`` if none."""
        ...


@dataclass(frozen=True)
class IkStats:
    iterations: int
    position_error: float
    orientation_error: float


class Kinematics:
    """Forward kinematics and the grasp-frame Jacobian of the 7-DOF control plant."""

    def __init__(self, plant: MultibodyPlant | None = None) -> None:
        self.plant = plant or make_control_plant()
        self.context = self.plant.CreateDefaultContext()
        self.frame = self.plant.GetFrameByName("grasp", self.plant.GetModelInstanceByName("hand"))
        self.lower = self.plant.GetPositionLowerLimits()
        self.upper = self.plant.GetPositionUpperLimits()
        self.velocity_limits = self.plant.GetVelocityUpperLimits()

    def pose(self, q: np.ndarray) -> RigidTransform:
        self.plant.SetPositions(self.context, q)
        return self.frame.CalcPoseInWorld(self.context)

    def jacobian(self) -> np.ndarray:
        """6x7 spatial-velocity Jacobian of the grasp frame at the context's configuration."""
        return self.plant.CalcJacobianSpatialVelocity(
            self.context,
            JacobianWrtVariable.kV,
            self.frame,
            np.zeros(3),
            self.plant.world_frame(),
            self.plant.world_frame(),
        )

    def error(self, q: np.ndarray, X_WG: RigidTransform) -> np.ndarray:
        """6-vector (rotation as axis-angle, then translation) from the pose at q to X_WG."""
        X = self.pose(q)
        dR = X_WG.rotation().multiply(X.rotation().inverse())
        aa = dR.ToAngleAxis()
        return np.concatenate([aa.axis() * aa.angle(), X_WG.translation() - X.translation()])

    def within(self, q: np.ndarray, X_WG: RigidTransform) -> bool:
        e = self.error(q, X_WG)
        return bool(
            np.linalg.norm(e[3:]) <= POSITION_TOL
            and np.linalg.norm(e[:3]) <= ORIENTATION_TOL
            and np.all(q >= self.lower - 1e-9)
            and np.all(q <= self.upper + 1e-9)
        )


def _newton(
    kin: Kinematics,
    X_WG: RigidTransform,
    q: np.ndarray,
    damping: float,
    max_iterations: int,
    max_step: float,
    tol: float = 1e-6,
) -> tuple[np.ndarray, int]:
    """Damped least-squares iterations clamped to the joint limits; returns (q, iterations)."""
    q = np.clip(np.asarray(q, float), kin.lower, kin.upper)
    lam2 = damping * damping
    for it in range(1, max_iterations + 1):
        e = kin.error(q, X_WG)
        if np.linalg.norm(e) < tol:
            return q, it - 1
        J = kin.jacobian()
        # Joints pinned at a limit and pushed further out are dropped from this step.
        free = np.ones(7, bool)
        dq = J.T @ np.linalg.solve(J @ J.T + lam2 * np.eye(6), e)
        pinned = ((q <= kin.lower + 1e-9) & (dq < 0)) | ((q >= kin.upper - 1e-9) & (dq > 0))
        if pinned.any():
            free = ~pinned
            Jf = J[:, free]
            dq = np.zeros(7)
            dq[free] = Jf.T @ np.linalg.solve(Jf @ Jf.T + lam2 * np.eye(6), e)
        step = np.max(np.abs(dq))
        if step > max_step:
            dq *= max_step / step
        q = np.clip(q + dq, kin.lower, kin.upper)
    return q, max_iterations


class DlsIk:
    """Damped least squares, as the exercise prescribes: damping 0.05, at most 200 iterations.

    Each step is capped at 0.2 rad per joint: uncapped, damping 0.05 overshoots into the
    joint limits on far targets.
    """

    name = "dls"

    def __init__(
        self,
        kinematics: Kinematics | None = None,
        damping: float = 0.05,
        max_iterations: int = 200,
        max_step: float = 0.2,
    ) -> None:
        self.kin = kinematics or Kinematics()
        self.damping = damping
        self.max_iterations = max_iterations
        self.max_step = max_step
        self.last_iterations = 0

    def solve(self, X_WG: RigidTransform, q_seed: np.ndarray) -> np.ndarray | None:
        q, self.last_iterations = _newton(
            self.kin, X_WG, q_seed, self.damping, self.max_iterations, self.max_step
        )
        return q if self.kin.within(q, X_WG) else None


class DrakeIk:
    """Drake ``InverseKinematics``, with a Gauss-Newton front end and seeded restarts.

    Order of attempts: (1) 30 lightly damped Newton steps from the seed; (2) the
    ``InverseKinematics`` program from the seed, then from home and from ``restarts``
    random configurations (seeded, so runs repeat), each answer polished by Newton steps
    (Drake imposes orientation as trace(R) >= 2cos(tol) + 1, so the solver's feasibility
    tolerance can leave ~1e-3 rad) and checked by forward kinematics.
    """

    name = "drake"

    def __init__(
        self,
        kinematics: Kinematics | None = None,
        restarts: int = 8,
        seed: int = 0,
        newton_first: bool = True,
    ) -> None:
        self.kin = kinematics or Kinematics()
        self.restarts = restarts
        self.newton_first = newton_first
        self._rng = np.random.default_rng(seed)
        self._seed = seed

    def _program(self, X_WG: RigidTransform, q_seed: np.ndarray):
        plant = self.kin.plant
        ik = InverseKinematics(plant, with_joint_limits=True)
        p = X_WG.translation()
        ik.AddPositionConstraint(
            self.kin.frame, np.zeros(3), plant.world_frame(), p - POSITION_TOL / 2, p + POSITION_TOL / 2
        )
        ik.AddOrientationConstraint(
            self.kin.frame, RotationMatrix(), plant.world_frame(), X_WG.rotation(), ORIENTATION_TOL / 2
        )
        q = ik.q()
        ik.prog().AddQuadraticErrorCost(np.eye(7) * 0.01, q_seed, q)
        return ik

    def solve(self, X_WG: RigidTransform, q_seed: np.ndarray) -> np.ndarray | None:
        q_seed = np.asarray(q_seed, float)
        if self.newton_first:
            q, _ = _newton(self.kin, X_WG, q_seed, 1e-3, 30, 0.6)
            if self.kin.within(q, X_WG):
                return q
        rng = np.random.default_rng(self._seed)  # same restarts for the same query
        seeds = [q_seed, Q_HOME] + [
            rng.uniform(self.kin.lower, self.kin.upper) for _ in range(self.restarts)
        ]
        for start in seeds:
            ik = self._program(X_WG, q_seed)
            result = Solve(ik.prog(), np.clip(start, self.kin.lower, self.kin.upper))
            q = result.GetSolution(ik.q())
            if not np.all(np.isfinite(q)):
                continue
            q, _ = _newton(self.kin, X_WG, q, 1e-4, 5, 0.6)
            if self.kin.within(q, X_WG):
                return q
        return None


SOLVERS = {"drake": DrakeIk, "dls": DlsIk}


def make_solver(name: str, kinematics: Kinematics | None = None) -> IkSolver:
    """The IK solver registered as ``name`` (``drake`` or ``dls``)."""
    from cake_drake.errors import InputError

    try:
        cls = SOLVERS[name]
    except KeyError:
        raise InputError(
            f"unknown IK solver {name!r}; choose one of: {', '.join(SOLVERS)}"
        ) from None
    return cls(kinematics)
