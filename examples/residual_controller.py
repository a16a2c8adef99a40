"""A controller plug-in: computed torque plus a residual, the shape of a learned correction.

The chapters where layers become learned often keep the model-based controller and
learn only what it gets wrong: tau = tau_IDC + r(q, v, q_d, v_d). Here the residual
``r`` is a small LeafSystem with a linear model - viscous-friction feed-forward,
``r = friction * v_d`` per joint - where a network would go; Drake's
``InverseDynamicsController`` and an ``Adder`` do the rest.

Use it in a scenario::

    controller: !CustomController
      factory: examples.residual_controller:make
      options: {kp: 100.0, kd: 20.0, friction: 0.05}
"""

import numpy as np
from pydrake.systems.controllers import InverseDynamicsController
from pydrake.systems.framework import BasicVector, LeafSystem
from pydrake.systems.primitives import Adder


class LinearResidual(LeafSystem):
    """r = friction * v_d: the residual torque, from the desired state.

    .. pydrake_system::

        name: LinearResidual
        input_ports:
        - desired_state
        output_ports:
        - residual_torque
    """

    def __init__(self, friction: np.ndarray) -> None:
        super().__init__()
        self._friction = np.asarray(friction, float)
        self._desired = self.DeclareVectorInputPort("desired_state", BasicVector(14))
        self.DeclareVectorOutputPort("residual_torque", BasicVector(7), self._calc)

    def _calc(self, context, output) -> None:
        v_d = self._desired.Eval(context)[7:]
        output.SetFromVector(self._friction * v_d)


class ResidualComputedTorque:
    name = "computed-torque+residual"

    def __init__(self, kp: float, kd: float, friction: float) -> None:
        self.kp, self.kd, self.friction = kp, kd, friction

    def arm_pd_gains(self) -> None:
        return None  # all torque is computed here

    def add_to(self, builder, scene, desired_state, desired_acceleration):
        idc = builder.AddNamedSystem(
            "inverse_dynamics_controller",
            InverseDynamicsController(
                scene.control_plant,
                np.full(7, self.kp),
                np.zeros(7),
                np.full(7, self.kd),
                True,
            ),
        )
        residual = builder.AddNamedSystem("residual", LinearResidual(np.full(7, self.friction)))
        total = builder.AddNamedSystem("idc_plus_residual", Adder(2, 7))
        builder.Connect(
            scene.plant.get_state_output_port(scene.arm), idc.get_input_port_estimated_state()
        )
        builder.Connect(desired_state, idc.get_input_port_desired_state())
        builder.Connect(desired_acceleration, idc.get_input_port_desired_acceleration())
        builder.Connect(desired_state, residual.GetInputPort("desired_state"))
        builder.Connect(idc.get_output_port_control(), total.get_input_port(0))
        builder.Connect(residual.GetOutputPort("residual_torque"), total.get_input_port(1))
        builder.Connect(total.get_output_port(), scene.plant.get_actuation_input_port(scene.arm))
        return total.get_output_port()


def make(kp: float = 100.0, kd: float = 20.0, friction: float = 0.05) -> ResidualComputedTorque:
    """The factory a scenario names; ``options`` become its keyword arguments."""
    return ResidualComputedTorque(kp, kd, friction)
