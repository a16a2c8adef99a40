"""The dynamic layer's door: controller configs, and the one place a controller is chosen.

A controller is anything with the :class:`Controller` protocol: a ``name``, the gains it
wants on the plant's built-in (implicit) joint PD, if any, and ``add_to``, which adds its
systems to the builder and wires them from the reference's named ports to the arm's
actuation input. Two ship, each its own config type (the scenario's ``controller:``
section, chosen by YAML tag):

* :class:`ComputedTorque` (``!ComputedTorque``, ``--mode torque``) - Drake's
  ``InverseDynamicsController`` on the 7-DOF control plant:
  tau = M(q)(a_d + Kp e + Kd e') + C(q, v)v + g(q), gains in 1/s^2 and 1/s.
* :class:`JointPd` (``!JointPd``, ``--mode position``) - the plant's built-in joint PD on
  the desired state (implicit in SAP, so stable at 10 ms steps; gains in N m/rad and
  N m s/rad) plus the reference's inverse-dynamics feed-forward from Drake's
  ``InverseDynamics``: what a position-controlled robot's firmware does for you.

:class:`CustomController` (``!CustomController``) names a factory of the user's,
``module:attribute``, called with the config's ``options``; :func:`make_controller` is the
only function that tells the kinds apart.
"""

import inspect
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import ClassVar, Protocol

import numpy as np
from pydrake.systems.controllers import InverseDynamics, InverseDynamicsController, PidController
from pydrake.systems.framework import DiagramBuilder, OutputPort
from pydrake.systems.primitives import Adder, Saturation

from cake_drake.dynamic.residual import ResidualModel, check_bound
from cake_drake.errors import InputError
from cake_drake.paths import resolve_path
from cake_drake.plugins import PluginError, guarded, load_attribute, require
from cake_drake.world.scene import Scene

#: The Panda's joint torque limits (N m): 87 on joints 1-4, 12 on joints 5-7 (the URDF's
#: ``effort``). Every controller's torque passes :func:`limit_torque` on its way to the arm.
TORQUE_LIMITS = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)

#: Built-in joint PD gains of the position controller (N m/rad, N m s/rad).
POSITION_KP = (800.0, 800.0, 800.0, 800.0, 300.0, 200.0, 100.0)
POSITION_KD = (80.0, 80.0, 80.0, 80.0, 30.0, 20.0, 10.0)


class Controller(Protocol):
    """What the Diagram needs from a controller."""

    name: str

    def arm_pd_gains(self) -> tuple[Sequence[float], Sequence[float]] | None:
        """(kp, kd) per arm joint for the plant's built-in PD, or None to leave it off.

        Asked before the plant is finalized; with gains, the plant's desired-state input
        for the arm must be connected by :meth:`add_to`.
        """
        ...

    def add_to(
        self,
        builder: DiagramBuilder,
        scene: Scene,
        desired_state: OutputPort,
        desired_acceleration: OutputPort,
    ) -> OutputPort:
        """Add and wire the controller; return the port of the torque it commands (logged)."""
        ...


def per_joint(values: Sequence[float], what: str) -> np.ndarray:
    """One value for every joint, or seven; finite."""
    v = [float(x) for x in values]
    if len(v) not in (1, 7):
        raise InputError(f"{what} takes one value or seven (one per joint), got {len(v)}")
    if not all(math.isfinite(x) for x in v):
        raise InputError(f"{what} must be finite numbers, got {v}")
    return np.array(v * 7 if len(v) == 1 else v)


def _check_gains(kp: Sequence[float], kd: Sequence[float], where: str) -> None:
    p, d = per_joint(kp, f"{where}.kp"), per_joint(kd, f"{where}.kd")
    if np.any(p <= 0) or np.any(d < 0):
        raise InputError(f"{where}: gains must be kp > 0 and kd >= 0 (got kp={kp}, kd={kd})")


@dataclass
class ComputedTorque:
    """Drake's ``InverseDynamicsController``; ``kp`` (1/s^2), ``kd`` (1/s), ``ki`` (1/s^3,
    integral action on the joint error; 0 by default): one value or seven each."""

    kp: list[float] = field(default_factory=lambda: [100.0])
    kd: list[float] = field(default_factory=lambda: [20.0])
    ki: list[float] = field(default_factory=lambda: [0.0])
    #: A learned residual's folder (:mod:`cake_drake.dynamic.residual`), added to the
    #: IDC's torque: tau = tau_IDC + r(q, v, q_d, v_d, a_d, gripper). Empty: none.
    residual: str = ""
    name: ClassVar[str] = "torque"

    def check(self) -> None:
        _check_gains(self.kp, self.kd, "controller (ComputedTorque)")
        if np.any(per_joint(self.ki, "controller (ComputedTorque).ki") < 0):
            raise InputError(f"controller (ComputedTorque): ki must be >= 0 (got {self.ki})")
        if self.residual:
            self.residual_model()

    def residual_model(self):
        """The residual (refused in one line, exit 2, when it is none this arm can run)."""
        model = ResidualModel.load(resolve_path(self.residual))
        check_bound(model.bound_nm, TORQUE_LIMITS, f"controller.residual {self.residual}")
        return model

    def gains(self) -> tuple[np.ndarray, np.ndarray]:
        return per_joint(self.kp, "kp"), per_joint(self.kd, "kd")

    def arm_pd_gains(self) -> None:
        return None

    def add_to(self, builder, scene, desired_state, desired_acceleration) -> OutputPort:
        kp, kd = self.gains()
        ki = per_joint(self.ki, "ki")
        controller = builder.AddNamedSystem(
            "inverse_dynamics_controller",
            InverseDynamicsController(scene.control_plant, kp, ki, kd, True),
        )
        builder.Connect(
            scene.plant.get_state_output_port(scene.arm),
            controller.get_input_port_estimated_state(),
        )
        builder.Connect(desired_state, controller.get_input_port_desired_state())
        builder.Connect(desired_acceleration, controller.get_input_port_desired_acceleration())
        tau = controller.get_output_port_control()
        if self.residual:
            tau = self._add_residual(builder, scene, desired_acceleration, tau)
        builder.Connect(tau, scene.plant.get_actuation_input_port(scene.arm))
        return tau

    def _add_residual(self, builder, scene, desired_acceleration, tau_idc) -> OutputPort:
        from cake_drake.dynamic.residual import ResidualTorque

        residual = builder.AddNamedSystem(
            "residual", ResidualTorque(self.residual_model(), scene.control_plant, self.residual)
        )
        plant = scene.plant
        builder.Connect(plant.get_state_output_port(scene.arm), residual.GetInputPort("arm_state"))
        builder.Connect(
            plant.get_state_output_port(scene.hand), residual.GetInputPort("hand_state")
        )
        builder.Connect(desired_acceleration, residual.GetInputPort("desired_acceleration"))
        total = builder.AddNamedSystem("idc_plus_residual", Adder(2, 7))
        builder.Connect(tau_idc, total.get_input_port(0))
        builder.Connect(residual.GetOutputPort("residual_torque"), total.get_input_port(1))
        return total.get_output_port()


@dataclass
class JointPd:
    """The plant's built-in joint PD plus a feed-forward torque.

    ``feedforward: true`` (the default) adds the reference's inverse dynamics,
    M(q_d) a_d + C(q_d, v_d) v_d + g(q_d): what a position-controlled robot's firmware
    does. ``feedforward: false`` adds only gravity compensation g(q) at the *measured*
    state - "PD plus gravity", the baseline of drill 4.x.2 (PyBullet's position control
    is a PD on the joint error with gravity compensation and no model of the motion).
    """

    kp: list[float] = field(default_factory=lambda: list(POSITION_KP))
    kd: list[float] = field(default_factory=lambda: list(POSITION_KD))
    feedforward: bool = True
    name: ClassVar[str] = "position"

    def check(self) -> None:
        _check_gains(self.kp, self.kd, "controller (JointPd)")
        if not isinstance(self.feedforward, bool):
            raise InputError(
                f"controller (JointPd).feedforward must be true or false, got {self.feedforward!r}"
            )

    def gains(self) -> tuple[np.ndarray, np.ndarray]:
        return per_joint(self.kp, "kp"), per_joint(self.kd, "kd")

    def arm_pd_gains(self) -> tuple[np.ndarray, np.ndarray]:
        return self.gains()

    def add_to(self, builder, scene, desired_state, desired_acceleration) -> OutputPort:
        builder.Connect(desired_state, scene.plant.get_desired_state_input_port(scene.arm))
        if not self.feedforward:
            gravity = builder.AddNamedSystem("gravity_compensation", _gravity(scene))
            builder.Connect(
                scene.plant.get_state_output_port(scene.arm),
                gravity.get_input_port_estimated_state(),
            )
            out = gravity.get_output_port_generalized_force()
            builder.Connect(out, scene.plant.get_actuation_input_port(scene.arm))
            return out
        # Feed-forward: the torque the reference needs, M(q_d) a_d + C(q_d, v_d) v_d + g(q_d),
        # from Drake's InverseDynamics evaluated on the *desired* state; the PD corrects.
        feedforward = builder.AddNamedSystem(
            "feedforward",
            InverseDynamics(
                scene.control_plant, InverseDynamics.InverseDynamicsMode.kInverseDynamics
            ),
        )
        builder.Connect(desired_state, feedforward.get_input_port_estimated_state())
        builder.Connect(desired_acceleration, feedforward.get_input_port_desired_acceleration())
        builder.Connect(
            feedforward.get_output_port_generalized_force(),
            scene.plant.get_actuation_input_port(scene.arm),
        )
        return feedforward.get_output_port_generalized_force()


def _gravity(scene: Scene) -> InverseDynamics:
    """g(q) of the 7-DOF control plant (Drake's gravity-compensation mode)."""
    return InverseDynamics(
        scene.control_plant, InverseDynamics.InverseDynamicsMode.kGravityCompensation
    )


def gravity_term(builder: DiagramBuilder, scene: Scene) -> OutputPort:
    """g(q) of the measured arm, as a port (for the log the joint plot draws)."""
    gravity = builder.AddNamedSystem("gravity_term", _gravity(scene))
    builder.Connect(
        scene.plant.get_state_output_port(scene.arm), gravity.get_input_port_estimated_state()
    )
    return gravity.get_output_port_generalized_force()


def limit_torque(builder: DiagramBuilder, scene: Scene) -> OutputPort | None:
    """Clamp whatever drives the arm's actuation input to :data:`TORQUE_LIMITS`.

    The one place between every controller (shipped or a user's) and the arm: the
    controller has wired its torque to the plant; this reroutes that wire through a
    ``Saturation``. Returns the port of the torque the controller *requested* (before the
    clamp), for the saturation report, or None when nothing drives the input (a controller
    that uses the plant's built-in PD only, which the plant clamps to the same limits).
    """
    actuation = scene.plant.get_actuation_input_port(scene.arm)
    source = None
    for (dest_system, dest_index), (src_system, src_index) in builder.connection_map().items():
        if dest_system is scene.plant and dest_index == actuation.get_index():
            source = src_system.get_output_port(src_index)
    if source is None:
        return None
    limits = np.array(TORQUE_LIMITS)
    saturation = builder.AddNamedSystem("torque_limits", Saturation(-limits, limits))
    builder.Disconnect(source, actuation)
    builder.Connect(source, saturation.get_input_port())
    builder.Connect(saturation.get_output_port(), actuation)
    return source


#: The Panda's joint inertias at home, diag M(Q_HOME) of the control plant (kg m^2), from
#: which the !Pid gains are scaled so that every joint is the same loop.
HOME_INERTIA = (0.7947, 1.6439, 1.0668, 0.86, 0.0299, 0.04, 0.003)
#: The !Pid loop's natural frequency per joint (rad/s).
PID_OMEGA = (15.0, 30.0, 15.0, 30.0, 30.0, 30.0, 30.0)
PID_KP = tuple(round(m * w**2, 3) for m, w in zip(HOME_INERTIA, PID_OMEGA, strict=True))
PID_KD = tuple(round(m * 2 * w, 3) for m, w in zip(HOME_INERTIA, PID_OMEGA, strict=True))
#: Largest Kd M^-1 eigenvalue times the step the explicit loop tolerates. 2 is the
#: stability edge of an explicitly integrated damper; measured on the exercise, 0.89
#: (the defaults at 1 ms) and 0.71 ring and saturate joints 1 and 3 in bursts, 0.45
#: (0.5 ms) tracks cleanly.
PID_MAX_STEP_RATIO = 0.5
PID_KI = tuple(round(m * 2 * w**2, 3) for m, w in zip(HOME_INERTIA, PID_OMEGA, strict=True))


@dataclass
class Pid:
    """Drake's ``PidController`` on the joint error plus gravity compensation g(q).

    tau = Kp e + Ki integral(e) + Kd e' + g(q), gains in N m/rad, N m/(rad s), N m s/rad,
    one or seven. Unlike the plant's built-in PD this torque is *explicit*: the plant holds
    it over each step, so the loop is stable only while its fastest mode moves little per
    step. The defaults give every joint the same loop whatever its inertia: Kp = I w^2,
    Kd = 2 I w (critically damped), Ki = 2 I w^2 (characteristic polynomial
    s^3 + 2w s^2 + w^2 s + 2w^2: stable, the integral pole slow), with I the joint's
    inertia at home (:data:`HOME_INERTIA`) and w (:data:`PID_OMEGA`) 15 rad/s on joints 1
    and 3, 30 on the others. The arm is coupled, though: at home joints 1 and 3 are nearly
    aligned, and counter-rotating they form a mode of little inertia where the largest
    eigenvalue of Kd M^-1 is about 890 1/s. Explicit damping diverges when that times the
    step passes 2: at the 10 ms step (8.9) the arm flies apart; at 1 ms (0.89) it rings
    and saturates joints 1 and 3 in bursts, so the defaults need ``world.time_step:
    0.0005`` (0.45); at w = 10 on 1-4 the shoulder trails by 40 mrad (3 cm at the hand),
    too much to grasp a 4 cm cube. :meth:`add_to` computes these figures and refuses,
    before simulating, a step where they exceed :data:`PID_MAX_STEP_RATIO`. With no
    inertial feed-forward the arm trails the reference by about a / w^2: the exercise's
    ``pid`` scenario slows the moves and holds the arm before each grasp and release, and
    builds the tower. The integral removes the steady error a model mismatch leaves (an
    unknown payload); a PD cannot.
    """

    kp: list[float] = field(default_factory=lambda: list(PID_KP))
    ki: list[float] = field(default_factory=lambda: list(PID_KI))
    kd: list[float] = field(default_factory=lambda: list(PID_KD))
    name: ClassVar[str] = "pid"

    def check(self) -> None:
        _check_gains(self.kp, self.kd, "controller (Pid)")
        ki = per_joint(self.ki, "controller (Pid).ki")
        if np.any(ki < 0):
            raise InputError(f"controller (Pid): ki must be >= 0 (got ki={self.ki})")

    def gains(self) -> tuple[np.ndarray, np.ndarray]:
        return per_joint(self.kp, "kp"), per_joint(self.kd, "kd")

    def arm_pd_gains(self) -> None:
        return None

    def stability(self, scene: Scene, time_step: float) -> tuple[float, float]:
        """(max eigenvalue of Kd M^-1, max sqrt eigenvalue of Kp M^-1) times ``time_step``
        at home: the fastest modes of the explicit loop per step (the coupled arm's, not
        one joint's: joints 1 and 3 counter-rotating have little inertia)."""
        from scipy.linalg import eigh

        from cake_drake.world.scene import Q_HOME

        plant = scene.control_plant
        context = plant.CreateDefaultContext()
        plant.SetPositions(context, Q_HOME)
        M = plant.CalcMassMatrix(context)
        kp, kd = self.gains()
        damping = float(eigh(np.diag(kd), M, eigvals_only=True).max())
        stiffness = float(np.sqrt(eigh(np.diag(kp), M, eigvals_only=True).max()))
        return damping * time_step, stiffness * time_step

    def add_to(self, builder, scene, desired_state, desired_acceleration) -> OutputPort:
        dt = scene.plant.time_step()
        damping, stiffness = self.stability(scene, dt)
        if damping > PID_MAX_STEP_RATIO or stiffness > PID_MAX_STEP_RATIO / 2:
            largest = dt * min(PID_MAX_STEP_RATIO / damping, PID_MAX_STEP_RATIO / 2 / stiffness)
            raise InputError(
                f"controller (Pid): unstable at world.time_step {dt:g} s: its fastest mode "
                f"moves {damping:.2f} (damping) and {stiffness:.2f} (stiffness) per step, "
                f"more than {PID_MAX_STEP_RATIO:g} and {PID_MAX_STEP_RATIO / 2:g}; use "
                f"world.time_step <= {largest:.2g} or lower gains"
            )
        kp, kd = self.gains()
        pid = builder.AddNamedSystem(
            "pid_controller", PidController(kp, per_joint(self.ki, "ki"), kd)
        )
        gravity = builder.AddNamedSystem("gravity_compensation", _gravity(scene))
        total = builder.AddNamedSystem("pid_plus_gravity", Adder(2, 7))
        state = scene.plant.get_state_output_port(scene.arm)
        builder.Connect(state, pid.get_input_port_estimated_state())
        builder.Connect(desired_state, pid.get_input_port_desired_state())
        builder.Connect(state, gravity.get_input_port_estimated_state())
        builder.Connect(pid.get_output_port_control(), total.get_input_port(0))
        builder.Connect(gravity.get_output_port_generalized_force(), total.get_input_port(1))
        builder.Connect(total.get_output_port(), scene.plant.get_actuation_input_port(scene.arm))
        return total.get_output_port()


@dataclass
class CustomController:
    """A controller of the user's: ``factory`` (``module:attribute``) called as
    ``factory(**options)`` must return an object with the :class:`Controller` protocol."""

    factory: str = ""
    options: dict[str, float] = field(default_factory=dict)

    def check(self) -> None:
        make_controller(self)


#: The controller configs a scenario's ``controller:`` section can hold (by YAML tag).
ControllerConfig = ComputedTorque | JointPd | Pid | CustomController
#: ``--mode`` names of the shipped controllers.
MODES = {"torque": ComputedTorque, "position": JointPd, "pid": Pid}


def make_controller(config: ControllerConfig) -> Controller:
    """The controller a config describes: the one place that tells the kinds apart."""
    if not isinstance(config, CustomController):
        return config
    factory = load_attribute(config.factory, "controller factory")
    if not callable(factory):
        raise InputError(f"controller factory {config.factory!r} is not callable")
    try:
        inspect.signature(factory).bind(**config.options)
    except TypeError as e:
        raise InputError(
            f"controller factory {config.factory!r} does not take options "
            f"{sorted(config.options)}: {e}"
        ) from None
    except ValueError:  # no signature to read (a builtin): let the call tell
        pass
    label = f"controller factory {config.factory!r}"
    controller = guarded(label, factory, **config.options)
    require(controller, config.factory, "controller", ("name", "arm_pd_gains", "add_to"))
    return _GuardedController(controller, config.factory)


class _GuardedController:
    """A user's controller whose calls at build time are guarded, and whose ``add_to`` is
    checked to return the arm's torque port (7 values)."""

    def __init__(self, controller, spec: str) -> None:
        self._controller = controller
        self._spec = spec
        self.name = controller.name

    def __getattr__(self, name: str):
        return getattr(self._controller, name)

    def arm_pd_gains(self):
        return guarded(f"controller {self._spec!r}", self._controller.arm_pd_gains)

    def add_to(self, builder, scene, desired_state, desired_acceleration):
        label = f"controller {self._spec!r}"
        tau = guarded(
            label, self._controller.add_to, builder, scene, desired_state, desired_acceleration
        )
        if not isinstance(tau, OutputPort) or tau.size() != 7:
            shown = (
                f"a port of size {tau.size()}"
                if isinstance(tau, OutputPort)
                else (f"a {type(tau).__name__}")
            )
            raise PluginError(
                f"{label}: add_to returned {shown}; it returns the OutputPort of the arm's 7 "
                "joint torques"
            )
        return tau
