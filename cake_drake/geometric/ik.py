"""Inverse kinematics behind one small interface, so a learned solver can drop in later.

An :class:`IkSolver` maps a desired grasp-frame pose ``X_WG`` and a seed configuration to
7 arm joint angles, or ``None``. Two solvers ship:

* :class:`DrakeIk` - Newton steps on Drake's kinematics from the seed, then from the
  nearest configurations of a precomputed table, then Drake's ``InverseKinematics``
  (position and orientation constraints, joint limits, a cost to stay near the seed,
  solved by SNOPT) as the constrained fallback. Every answer is checked against forward
  kinematics. Deterministic: the same query gives the same answer.
* :class:`DlsIk` - the exercise's damped least squares (damping 0.05, at most 200
  iterations) on Drake's Jacobian.

Both work on the 7-DOF control plant (:func:`cake_drake.world.scene.make_control_plant`)
and take their tolerances as constructor arguments (defaults :data:`POSITION_TOL` and
:data:`ORIENTATION_TOL`, which the pipeline uses; ``benchmarks/ik.py`` runs the TRAC-IK
protocol at 1e-5). Measured numbers are in ``docs/ik.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.solvers import Solve

from cake_drake.geometric.trajectory import JointLimits
from cake_drake.plugins import require, resolve
from cake_drake.world.scene import Q_HOME, make_control_plant

#: Default tolerances every solution is checked against, whatever the solver.
POSITION_TOL = 1e-4  # m
ORIENTATION_TOL = 1e-3  # rad

_I6 = np.eye(6)
_TABLE_STREAM = 0x7AB1E
_ZERO3 = np.zeros(3)


class IkSolver(Protocol):
    """What the geometric layer needs from an IK solver."""

    name: str

    def solve(self, X_WG: RigidTransform, q_seed: np.ndarray) -> np.ndarray | None:
        """Joint angles putting the grasp frame at ``X_WG``, near ``q_seed``; ``None`` if none."""
        ...


@dataclass(frozen=True)
class IkStats:
    """How the last :meth:`DrakeIk.solve` went: which stage answered and at what cost."""

    stage: str  # "seed", "table", "snopt" or "failed"
    iterations: int  # Newton iterations, all stages together
    programs: int  # InverseKinematics programs solved


class Kinematics:
    """Forward kinematics and the grasp-frame Jacobian of the 7-DOF control plant."""

    def __init__(self, plant: MultibodyPlant | None = None) -> None:
        self.plant = plant or make_control_plant()
        self.context = self.plant.CreateDefaultContext()
        self.frame = self.plant.GetFrameByName("grasp", self.plant.GetModelInstanceByName("hand"))
        self.lower = self.plant.GetPositionLowerLimits()
        self.upper = self.plant.GetPositionUpperLimits()
        self.mid = (self.lower + self.upper) / 2
        self.velocity_limits = self.plant.GetVelocityUpperLimits()
        self._world = self.plant.world_frame()
        # A bound on reach: the grasp frame is never farther from the first joint's origin
        # than the chain of joint origins is long (the links are rigid).
        context = self.plant.CreateDefaultContext()
        joints = [self.plant.get_joint(j) for j in self.plant.GetJointIndices()]
        origins = [j.frame_on_child().CalcPoseInWorld(context).translation() for j in joints
                   if j.num_positions() == 1]  # fmt: skip
        origins.append(self.frame.CalcPoseInWorld(context).translation())
        self.base = origins[0]
        self.reach = float(np.sum(np.linalg.norm(np.diff(origins, axis=0), axis=1)))

    @property
    def limits(self) -> JointLimits:
        """The arm's velocity and acceleration limits, as the plant has them."""
        return JointLimits.from_plant(self.plant)

    def pose(self, q: np.ndarray) -> RigidTransform:
        self.plant.SetPositions(self.context, q)
        return self.frame.CalcPoseInWorld(self.context)

    def pose34(self, q: np.ndarray) -> np.ndarray:
        """``X_WG`` at ``q`` as a 3x4 matrix [R | p] (the fast path of the solvers)."""
        self.plant.SetPositions(self.context, q)
        return self.frame.CalcPoseInWorld(self.context).GetAsMatrix34()

    def jacobian(self) -> np.ndarray:
        """6x7 spatial-velocity Jacobian of the grasp frame at the context's configuration."""
        return self.plant.CalcJacobianSpatialVelocity(
            self.context, JacobianWrtVariable.kV, self.frame, _ZERO3, self._world, self._world
        )

    def error(self, q: np.ndarray, X_WG: RigidTransform) -> np.ndarray:
        """6-vector (rotation as axis-angle, then translation) from the pose at q to X_WG."""
        return np.array(_error6(X_WG.GetAsMatrix34(), self.pose34(q)))

    def pose_errors(self, q: np.ndarray, X_WG: RigidTransform) -> tuple[float, float]:
        """(position error in m, orientation error in rad) of ``q`` against ``X_WG``.

        Computed independently of the solvers' error: the angle from the Frobenius
        distance of the rotations, ``|R1 - R2|_F = 2 sqrt(2) sin(angle / 2)``.
        """
        M, M_t = self.pose34(q), X_WG.GetAsMatrix34()
        chord = np.linalg.norm(M[:, :3] - M_t[:, :3]) / (2 * math.sqrt(2))
        return float(np.linalg.norm(M[:, 3] - M_t[:, 3])), 2 * math.asin(min(1.0, chord))

    def beyond_reach(self, X_WG: RigidTransform) -> bool:
        """True when no configuration can put the grasp frame at ``X_WG``'s position."""
        return float(np.linalg.norm(X_WG.translation() - self.base)) > self.reach

    def within_limits(self, q: np.ndarray) -> bool:
        return bool(np.all(q >= self.lower) and np.all(q <= self.upper))

    def within(
        self,
        q: np.ndarray,
        X_WG: RigidTransform,
        position_tol: float = POSITION_TOL,
        orientation_tol: float = ORIENTATION_TOL,
    ) -> bool:
        """Whether ``q`` is within the joint limits and puts the grasp frame at ``X_WG``."""
        if not np.all(np.isfinite(q)):
            return False
        dp, dr = self.pose_errors(q, X_WG)
        return dp <= position_tol and dr <= orientation_tol and self.within_limits(q)

    def newton(
        self,
        X_WG: RigidTransform | np.ndarray,
        q: np.ndarray,
        damping: float,
        max_iterations: int,
        max_step: float,
        tol: float,
        stall: float | None = None,
    ) -> tuple[np.ndarray, int, bool]:
        """Damped least-squares (Gauss-Newton) steps towards ``X_WG`` within the joint limits.

        Each step solves ``(J J^T + damping^2 I) y = e``, ``dq = J^T y`` for the 6-vector
        error ``e`` (axis-angle, then translation), leaves out the joints pinned at a
        limit that the error pushes further out, is capped at ``max_step`` rad per joint
        and clipped to the limits. Stops when ``|e| < tol`` (converged), after
        ``max_iterations``, or - with ``stall`` - from the fourth step on when ``|e|^2``
        shrank by less than that factor (no quadratic convergence: try another seed).
        Returns (q, iterations, converged).
        """
        M_t = X_WG if isinstance(X_WG, np.ndarray) else X_WG.GetAsMatrix34()
        lo, hi = self.lower, self.upper
        plant, context, frame, world = self.plant, self.context, self.frame, self._world
        kv = JacobianWrtVariable.kV
        lam2 = damping * damping * _I6
        q = np.minimum(np.maximum(np.asarray(q, float), lo), hi)
        tol2 = tol * tol
        previous = math.inf
        for it in range(max_iterations):
            plant.SetPositions(context, q)
            el = _error6(M_t, frame.CalcPoseInWorld(context).GetAsMatrix34())
            n = el[0] ** 2 + el[1] ** 2 + el[2] ** 2 + el[3] ** 2 + el[4] ** 2 + el[5] ** 2
            if n < tol2:
                return q, it, True
            if stall is not None and it >= 3 and n > stall * previous:
                return q, it, False
            previous = n
            e = np.array(el)
            J = plant.CalcJacobianSpatialVelocity(context, kv, frame, _ZERO3, world, world)
            at_limit = (q <= lo) | (q >= hi)
            if at_limit.any():
                g = J.T @ e  # the direction each joint would move to reduce the error
                pinned = at_limit & (((q <= lo) & (g < 0)) | ((q >= hi) & (g > 0)))
                J = J * ~pinned
            dq = J.T @ np.linalg.solve(J @ J.T + lam2, e)
            biggest = max(dq.max(), -dq.min())
            if biggest > max_step:
                dq *= max_step / biggest
            q = np.minimum(np.maximum(q + dq, lo), hi)
        plant.SetPositions(context, q)
        el = _error6(M_t, frame.CalcPoseInWorld(context).GetAsMatrix34())
        return q, max_iterations, sum(v * v for v in el) < tol2


def _error6(M_t: np.ndarray, M: np.ndarray) -> list[float]:
    """[rotation vector of R_t R^T, p_t - p] for 3x4 poses (target, current), as floats."""
    (a, b, c), (d, e, f), (g, h, i) = (M_t[:, :3] @ M[:, :3].T).tolist()
    x, y, z = 0.5 * (h - f), 0.5 * (c - g), 0.5 * (d - b)  # sin(angle) * axis
    s = math.sqrt(x * x + y * y + z * z)
    cos = 0.5 * (a + e + i - 1.0)
    if s > 1e-9:
        k = math.atan2(s, cos) / s
    elif cos > 0:
        k = 1.0
    else:  # a half turn: the axis is the dominant column of R + I
        R = M_t[:, :3] @ M[:, :3].T + np.eye(3)
        j = int(np.argmax(np.diag(R)))
        x, y, z = (R[:, j] / np.linalg.norm(R[:, j]) * math.pi).tolist()
        k = 1.0
    dx, dy, dz = (M_t[:, 3] - M[:, 3]).tolist()
    return [k * x, k * y, k * z, dx, dy, dz]


def _stop_tol(position_tol: float, orientation_tol: float) -> float:
    """Newton's stopping norm: a tenth of the tighter tolerance (one more quadratic step)."""
    return 0.1 * min(position_tol, orientation_tol)


class DlsIk:
    """Damped least squares, as the exercise prescribes: damping 0.05, at most 200 iterations.

    One attempt from the seed. Each step is capped at 0.2 rad per joint: uncapped,
    damping 0.05 overshoots into the joint limits on far targets.
    """

    name = "dls"

    def __init__(
        self,
        kinematics: Kinematics | None = None,
        damping: float = 0.05,
        max_iterations: int = 200,
        max_step: float = 0.2,
        position_tol: float = POSITION_TOL,
        orientation_tol: float = ORIENTATION_TOL,
    ) -> None:
        self.kin = kinematics or Kinematics()
        self.damping = damping
        self.max_iterations = max_iterations
        self.max_step = max_step
        self.position_tol = position_tol
        self.orientation_tol = orientation_tol
        self.last_iterations = 0

    def solve(self, X_WG: RigidTransform, q_seed: np.ndarray) -> np.ndarray | None:
        tol = _stop_tol(self.position_tol, self.orientation_tol)
        q, self.last_iterations, _ = self.kin.newton(
            X_WG, q_seed, self.damping, self.max_iterations, self.max_step, tol
        )
        return q if self.kin.within(q, X_WG, self.position_tol, self.orientation_tol) else None


class DrakeIk:
    """Newton on Drake's kinematics from the seed and from a table, Drake IK as fallback.

    Stages, each answer checked by forward kinematics at the solver's tolerances:

    1. When the seed's grasp pose is within ``near`` of ``X_WG`` (poses compared as
       [p, 0.3 m * R]; consecutive tabletop waypoints are 0.1-0.7 apart, random poses
       ~1.1 from the mid-limits configuration's): ``seed_iterations`` lightly damped
       Newton steps from ``q_seed``, then one ``InverseKinematics`` program from it.
       Seeded with the previous waypoint's solution, the pipeline's waypoints converge
       here in a handful of steps and stay on the seed's branch.
    2. Newton from the ``table_tries`` configurations of a table (``table_size`` random
       configurations within the limits, drawn once from ``seed``, built on first need,
       ~75 ms) whose grasp poses are nearest to ``X_WG``, at most ``table_iterations``
       steps each; a try whose squared error shrinks by less than ``stall`` in a step
       (from the fourth on) is abandoned for the next. Then, for a far seed, Newton from
       the seed; then the same table configurations again, with twice the steps and no
       early abandon (poses reachable only near the joint limits converge slowly).
    3. Drake's ``InverseKinematics`` solved by SNOPT (a cost keeps it near the seed) from
       the seed, home and ``restarts`` table configurations, each answer polished by
       Newton steps: Drake imposes the orientation as trace(R) >= 2cos(tol) + 1, so the
       solver's feasibility tolerance alone leaves up to ~1e-3 rad.

    A position farther than the arm's chain of joints is long fails at once.
    Nothing depends on earlier queries or on the clock, so the same query always gives
    the same answer. :attr:`last` tells which stage answered.
    """

    name = "drake"

    def __init__(
        self,
        kinematics: Kinematics | None = None,
        restarts: int = 8,
        seed: int = 0,
        newton_first: bool = True,
        position_tol: float = POSITION_TOL,
        orientation_tol: float = ORIENTATION_TOL,
        seed_iterations: int = 10,
        table_size: int = 4000,
        table_tries: int = 60,
        table_iterations: int = 15,
        near: float = 0.75,
        stall: float = 0.7,
    ) -> None:
        self.kin = kinematics or Kinematics()
        self.restarts = restarts
        self.newton_first = newton_first
        self.position_tol = position_tol
        self.orientation_tol = orientation_tol
        self.seed_iterations = seed_iterations
        self.table_size = table_size
        self.table_tries = table_tries
        self.table_iterations = table_iterations
        self.near = near
        self.stall = stall
        self._seed = seed
        self._table: _PoseTable | None = None
        self.last = IkStats("failed", 0, 0)

    @property
    def table(self) -> _PoseTable:
        if self._table is None:
            self._table = _PoseTable(self.kin, self.table_size, self._seed)
        return self._table

    def _newton(self, M_t: np.ndarray, q: np.ndarray, iterations: int, stall: float | None):
        tol = _stop_tol(self.position_tol, self.orientation_tol)
        return self.kin.newton(M_t, q, 1e-3, iterations, 0.6, tol, stall)

    def _program(self, X_WG: RigidTransform, q_seed: np.ndarray) -> InverseKinematics:
        plant = self.kin.plant
        ik = InverseKinematics(plant, with_joint_limits=True)
        p = X_WG.translation()
        box = np.full(3, self.position_tol / 2)
        ik.AddPositionConstraint(self.kin.frame, _ZERO3, plant.world_frame(), p - box, p + box)
        ik.AddOrientationConstraint(
            self.kin.frame, RotationMatrix(), plant.world_frame(), X_WG.rotation(),
            self.orientation_tol / 2,
        )  # fmt: skip
        ik.prog().AddQuadraticErrorCost(np.eye(7) * 0.01, q_seed, ik.q())
        return ik

    def _snopt(self, X_WG: RigidTransform, q_seed: np.ndarray, start: np.ndarray):
        """InverseKinematics from ``start`` (cost: stay near ``q_seed``), Newton-polished."""
        ik = self._program(X_WG, q_seed)
        result = Solve(ik.prog(), np.clip(start, self.kin.lower, self.kin.upper))
        q = result.GetSolution(ik.q())
        if not np.all(np.isfinite(q)):
            return None, 0
        q, it, _ = self._newton(X_WG.GetAsMatrix34(), q, 10, stall=None)
        return q, it

    def solve(self, X_WG: RigidTransform, q_seed: np.ndarray) -> np.ndarray | None:
        q_seed = np.asarray(q_seed, float)
        M_t = X_WG.GetAsMatrix34()
        tols = (self.position_tol, self.orientation_tol)
        iterations = programs = 0
        if self.kin.beyond_reach(X_WG):
            self.last = IkStats("failed", 0, 0)
            return None

        def done(stage: str, q: np.ndarray | None) -> np.ndarray | None:
            self.last = IkStats(stage, iterations, programs)
            return q

        def newton_from(q0: np.ndarray, budget: int, stall: float | None) -> np.ndarray | None:
            nonlocal iterations
            q, it, _ = self._newton(M_t, q0, budget, stall)
            iterations += it
            return q if self.kin.within(q, X_WG, *tols) else None

        def snopt_from(start: np.ndarray) -> np.ndarray | None:
            nonlocal iterations, programs
            q, it = self._snopt(X_WG, q_seed, start)
            iterations, programs = iterations + it, programs + 1
            return q if q is not None and self.kin.within(q, X_WG, *tols) else None

        seed_near = self.newton_first and (
            _pose_distance(self.kin.pose34(q_seed), M_t) <= self.near
        )
        if seed_near:  # the pipeline's case: stay on the seed's branch if at all possible
            if (q := newton_from(q_seed, self.seed_iterations, None)) is not None:
                return done("seed", q)
            if (q := snopt_from(q_seed)) is not None:
                return done("snopt", q)
        nearest = self.table.nearest(M_t, max(self.table_tries, self.restarts))
        for i in nearest[: self.table_tries]:
            if (q := newton_from(self.table.q[i], self.table_iterations, self.stall)) is not None:
                return done("table", q)
        if self.newton_first and not seed_near:
            if (q := newton_from(q_seed, 3 * self.seed_iterations, None)) is not None:
                return done("seed", q)
        for i in nearest[: self.table_tries]:  # again, patiently: near joint limits
            if (q := newton_from(self.table.q[i], 2 * self.table_iterations, None)) is not None:
                return done("table", q)
        starts = [] if seed_near else [q_seed]
        starts += [Q_HOME] + [self.table.q[i] for i in nearest[: self.restarts]]
        for start in starts:
            if (q := snopt_from(start)) is not None:
                return done("snopt", q)
        return done("failed", None)


#: Weight of the rotation matrix against the position (m) when comparing poses: a radian
#: of rotation counts about as much as 0.4 m of translation.
_ROTATION_WEIGHT = 0.3


def _feature(M: np.ndarray) -> np.ndarray:
    """A 3x4 pose as the 12-vector [p, w R] whose Euclidean distance compares poses."""
    return np.concatenate([M[:, 3], _ROTATION_WEIGHT * M[:, :3].ravel()])


def _pose_distance(M1: np.ndarray, M2: np.ndarray) -> float:
    return float(np.linalg.norm(_feature(M1) - _feature(M2)))


class _PoseTable:
    """Random configurations within the limits and their grasp poses, for seeding Newton."""

    def __init__(self, kin: Kinematics, size: int, seed: int) -> None:
        rng = np.random.default_rng([_TABLE_STREAM, seed])  # not any user's default_rng(seed)
        self.q = rng.uniform(kin.lower, kin.upper, (size, 7))
        self.features = np.array([_feature(kin.pose34(q)) for q in self.q])
        self.norms = np.einsum("ij,ij->i", self.features, self.features)

    def nearest(self, M: np.ndarray, k: int) -> np.ndarray:
        """Indices of the ``k`` configurations whose poses are nearest ``M``, nearest first."""
        k = min(k, len(self.q))
        d = self.norms - 2 * (self.features @ _feature(M))
        idx = np.argpartition(d, k - 1)[:k]
        return idx[np.argsort(d[idx], kind="stable")]


#: IK solvers by name, each a factory ``(kinematics, seed) -> IkSolver``; a scenario names
#: one of these or a factory of its own as ``module:attribute`` (see :func:`make_solver`).
SOLVERS = {
    "drake": lambda kinematics, seed: DrakeIk(kinematics, seed=seed),
    "dls": lambda kinematics, seed: DlsIk(kinematics),  # deterministic: nothing to seed
}


def make_solver(spec: str, kinematics: Kinematics | None = None, seed: int = 0) -> IkSolver:
    """The IK solver ``spec`` names: ``drake``, ``dls`` or ``module:attribute`` of a factory
    ``(kinematics, seed) -> IkSolver``; the result is checked for ``name`` and ``solve``."""
    factory = resolve(spec, SOLVERS, "IK solver")
    solver = factory(kinematics or Kinematics(), seed)
    require(solver, spec, "IK solver", ("name", "solve"))
    return solver
