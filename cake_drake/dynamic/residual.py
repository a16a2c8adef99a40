"""The dynamic layer's learned part: a residual torque beside computed torque (§4.4).

``InverseDynamicsController`` computes tau_IDC = M(q)(a_d + Kp e + Kd e') + C(q, v)v + g(q)
from its model, the 7-DOF arm of :func:`cake_drake.world.scene.make_control_plant`. What
the model lacks (a carried cube's mass, a payload, joint friction) the feedback must
make up, and Kp and Kd cannot remove a steady load. A residual adds what is missing:

    tau = tau_IDC + r(q, v, q_d, v_d, a_d, gripper)

**The model of r.** Linear in features of the arm's own kinematics, per joint j:

===================  ===========================================================
``hold_gravity``      h * G_j(q)        (a unit mass at the grasp frame, held up)
``hold_inertia``      h * (J^T J a_d)_j (the same mass, accelerated as planned)
``gravity``           G_j(q)            (a mass there all the time: a payload)
``inertia``           (J^T J a_d)_j
``velocity``          v_j               (viscous friction)
===================  ===========================================================

with J(q) the grasp frame's translational Jacobian, G(q) = J^T (0, 0, 9.81) and h = 1
while the hand holds a cube (one finger's measured opening within :data:`HOLD`), else 0.
Seven rows of five weights: 35 numbers, fitted by least squares in milliseconds, about
a kilobyte on disk. A carried mass m makes exactly m * (hold_gravity + hold_inertia), so
the model can be right; what it learns is how much, joint by joint.

**The label.** On a logged run, ``tau_applied - tau_model(q, v, a)``: the torque that
drove the arm, less what the model says that motion needs, at the measured state and
the measured acceleration a = (v[k+1] - v[k]) / h. The plant is discrete with step h and
holds the actuation computed from the state at t_k over the step to t_(k+1) (the plant's
net actuation port reports it at t_(k+1)), so that difference is exactly the
acceleration the step applied: the label is the unmodelled generalised force itself
(with the sign that cancels it), with no filtering lag and no bias, up to the contact
forces inside a step. (Paired one sample off, the same run's labels are ten to twenty
times noisier in free motion.)

A residual is a folder: ``residual.json`` (what it is, its features, weights, bound and
how it was fitted). ``controller: !ComputedTorque {residual: DIR}`` adds it inside the
Diagram (:class:`ResidualTorque` and an ``Adder`` beside the IDC); its torque is clipped
to ``bound_nm`` per joint, and the torque limits apply after, as to every controller.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import BasicVector, LeafSystem

from cake_drake.errors import ExecutionError, InputError

FEATURES = ("hold_gravity", "hold_inertia", "gravity", "inertia", "velocity")
#: One finger's measured opening (m) while a 4 cm cube is held between the two: the
#: fingers stop at 2 cm each; open they stand at 4 cm, shut on nothing at 0.
HOLD = (0.012, 0.028)
#: What a residual's folder holds.
FILE = "residual.json"
KIND = "residual on computed torque"
ARM = 7
GRAVITY = 9.81


@dataclass
class ResidualModel:
    """r = clip(sum_k weights[j, k] * features[j, k], -bound, bound) per joint j."""

    weights: list[list[float]]  # (7, len(FEATURES))
    bound_nm: list[float] = field(default_factory=lambda: [10.0] * 4 + [3.0] * 3)
    features: list[str] = field(default_factory=lambda: list(FEATURES))
    #: How it was made: the runs, samples, fit error (free-form, for people).
    fit: dict = field(default_factory=dict)
    kind: str = KIND
    joints: int = ARM

    def save(self, folder: Path) -> Path:
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / FILE
        path.write_text(json.dumps(asdict(self), indent=2) + "\n")
        return path

    @classmethod
    def load(cls, folder: Path) -> ResidualModel:
        """The residual in ``folder``; one line (exit 2) for anything that is not one this
        arm and these features can run."""
        folder = Path(folder)
        path = folder / FILE if folder.is_dir() else folder
        if not path.is_file():
            raise InputError(f"{folder}: no residual here (no {FILE}); make one with "
                             "python -m cake_drake.train --residual RUNS --out DIR")  # fmt: skip
        try:
            data = json.loads(path.read_text())
        except (OSError, ValueError) as e:
            raise InputError(f"{path}: unreadable ({e})") from None
        if not isinstance(data, dict) or data.get("kind") != KIND:
            kind = data.get("kind") if isinstance(data, dict) else type(data).__name__
            raise InputError(f"{path}: a {kind!r}, not a {KIND!r}")
        if data.get("joints") != ARM:
            raise InputError(f"{path}: a residual for {data.get('joints')} joints; the Panda "
                             f"has {ARM}")  # fmt: skip
        if data.get("features") != list(FEATURES):
            raise InputError(f"{path}: trained on inputs {data.get('features')}; this "
                             f"residual reads {list(FEATURES)}")  # fmt: skip
        try:
            w = np.asarray(data.get("weights"), float)
            b = np.asarray(data.get("bound_nm"), float)
        except (TypeError, ValueError):  # strings, nested lists of unequal length, null
            w = b = np.empty(0)
        if w.shape != (ARM, len(FEATURES)) or b.shape != (ARM,):
            raise InputError(f"{path}: weights must be {ARM} x {len(FEATURES)} and bound_nm "
                             f"{ARM} numbers")  # fmt: skip
        if not (np.all(np.isfinite(w)) and np.all(np.isfinite(b)) and np.all(b >= 0)):
            raise InputError(f"{path}: weights and bounds must be finite (bounds >= 0)")
        return cls(**{k: data[k] for k in cls.__dataclass_fields__ if k in data})

    def torque(self, phi: np.ndarray) -> np.ndarray:
        """r for features ``phi`` (7, K), or a batch (N, 7, K)."""
        raw = np.einsum("...jk,jk->...j", phi, np.asarray(self.weights))
        bound = np.asarray(self.bound_nm)
        return np.clip(raw, -bound, bound)


def load_model(folder: str | Path) -> ResidualModel:
    """The checked residual in ``folder`` (:meth:`ResidualModel.load`), as
    :mod:`cake_drake.artifacts` loads every learned thing."""
    return ResidualModel.load(Path(folder))


def holding(opening: float) -> float:
    """1 while one finger's measured opening says a cube is held (:data:`HOLD`), else 0."""
    return 1.0 if HOLD[0] <= opening <= HOLD[1] else 0.0


class Kinematics:
    """The control plant's grasp-frame Jacobian, for the features."""

    def __init__(self, control_plant) -> None:
        self.plant = control_plant
        self.context = control_plant.CreateDefaultContext()
        self.grasp = control_plant.GetFrameByName("grasp")
        self.world = control_plant.world_frame()
        self._origin = np.zeros(3)

    def terms(self, q, a_d) -> tuple[np.ndarray, np.ndarray]:
        """G(q) and J^T J a_d: a unit mass at the grasp frame, held up and accelerated."""
        self.plant.SetPositions(self.context, q)
        J = self.plant.CalcJacobianTranslationalVelocity(
            self.context, JacobianWrtVariable.kV, self.grasp, self._origin,
            self.world, self.world,
        )  # fmt: skip
        return J[2] * GRAVITY, J.T @ (J @ a_d)

    def features(self, q, v, a_d, opening: float) -> np.ndarray:
        """(7, K): :data:`FEATURES` per joint at one state."""
        gravity, inertia = self.terms(q, a_d)
        h = holding(opening)
        return np.stack([h * gravity, h * inertia, gravity, inertia, np.asarray(v)], axis=1)

    def model_torque(self, q, v, a) -> np.ndarray:
        """M(q) a + C(q, v) v - g(q): what the model says the motion needs."""
        self.plant.SetPositions(self.context, q)
        self.plant.SetVelocities(self.context, v)
        M = self.plant.CalcMassMatrix(self.context)
        bias = self.plant.CalcBiasTerm(self.context)
        g = self.plant.CalcGravityGeneralizedForces(self.context)
        return M @ a + bias - g


def samples(logs, kin: Kinematics) -> tuple[np.ndarray, np.ndarray]:
    """Features (N - 1, 7, K) and labels (N - 1, 7) of a run's logs (see the module).

    Sample k of the logs holds the state x_k and, as ``tau_applied``, the actuation of
    the step that ended there (the plant's net actuation port reports the step just
    taken): the step from x_(k-1) to x_k applied ``tau_applied[k]`` and the acceleration
    (v_k - v_(k-1)) / h, from the state x_(k-1) whose features are paired with it."""
    t = np.asarray(logs.t)
    a = np.diff(logs.v, axis=0) / np.diff(t)[:, None]
    n = len(a)
    phi = np.empty((n, ARM, len(FEATURES)))
    label = np.empty((n, ARM))
    for k in range(n):
        q, v = logs.q[k], logs.v[k]
        phi[k] = kin.features(q, v, logs.a_d[k], float(logs.fingers[k]))
        label[k] = logs.tau_applied[k + 1] - kin.model_torque(q, v, a[k])
    return phi, label


def fit(phi: np.ndarray, label: np.ndarray, ridge: float = 1e-6) -> np.ndarray:
    """Per joint, the weights that fit ``label`` from ``phi`` in least squares. A feature
    that is zero on a joint (a joint whose motion does not move the grasp point, such as
    the last) keeps weight 0, and a tiny ridge keeps one that hardly moved from taking
    an arbitrary weight."""
    weights = np.zeros((ARM, phi.shape[2]))
    for j in range(ARM):
        X, y = phi[:, j, :], label[:, j]
        scale = np.abs(X).max(axis=0)
        on = scale > 1e-6
        Xs = X[:, on] / scale[on]
        A = Xs.T @ Xs + ridge * len(Xs) * np.eye(Xs.shape[1])
        weights[j, on] = np.linalg.solve(A, Xs.T @ y) / scale[on]
    return weights


def from_mass(mass_kg: float, bound_nm: Sequence[float] | None = None) -> ResidualModel:
    """The residual of a held mass known exactly (the controller told the cube's mass):
    the floor a learned residual is measured against."""
    w = np.zeros((ARM, len(FEATURES)))
    w[:, 0] = w[:, 1] = mass_kg
    model = ResidualModel(weights=w.tolist(), fit={"from": f"a held mass of {mass_kg:g} kg"})
    if bound_nm is not None:
        model.bound_nm = [float(b) for b in bound_nm]
    return model


class ResidualTorque(LeafSystem):
    """r(q, v, q_d, v_d, a_d, gripper) of a :class:`ResidualModel` (see the module).

    .. pydrake_system::

        name: ResidualTorque
        input_ports:
        - arm_state
        - hand_state
        - desired_acceleration
        output_ports:
        - residual_torque

    A torque that is not finite stops the run (exit 3), naming the residual.
    """

    def __init__(self, model: ResidualModel, control_plant, name: str) -> None:
        super().__init__()
        self._w = np.asarray(model.weights, float)
        self._bound = np.asarray(model.bound_nm, float)
        self._kin = Kinematics(control_plant)
        self._name = name
        self._arm = self.DeclareVectorInputPort("arm_state", BasicVector(2 * ARM))
        self._hand = self.DeclareVectorInputPort("hand_state", BasicVector(4))
        self._accel = self.DeclareVectorInputPort("desired_acceleration", BasicVector(ARM))
        self.DeclareVectorOutputPort("residual_torque", BasicVector(ARM), self._calc)

    def _calc(self, context, output) -> None:
        # The model's sum written out per feature (a step's cost: one Jacobian, a few
        # vector operations): the same r as ResidualModel.torque(features).
        x = self._arm.Eval(context)
        h = holding(float(self._hand.Eval(context)[0]))
        gravity, inertia = self._kin.terms(x[:ARM], self._accel.Eval(context))
        w = self._w
        r = (w[:, 0] * h + w[:, 2]) * gravity + (w[:, 1] * h + w[:, 3]) * inertia
        r += w[:, 4] * x[ARM:]
        np.clip(r, -self._bound, self._bound, out=r)
        if not np.all(np.isfinite(r)):
            raise ExecutionError(f"residual {self._name}: a torque that is not finite at "
                                 f"t = {context.get_time():.3f} s")  # fmt: skip
        output.SetFromVector(r)


def check_bound(bound: Sequence[float], limits: Sequence[float], where: str) -> None:
    """A residual may not ask more than the arm's torque limits."""
    for b, limit in zip(bound, limits, strict=True):
        if not (math.isfinite(b) and 0 <= b <= limit):
            raise InputError(f"{where}: bound_nm {list(bound)} must be 0 to the torque "
                             f"limits {list(limits)}")  # fmt: skip
