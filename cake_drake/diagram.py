"""Builds the whole cake as one Drake Diagram. Nothing else in the project wires ports.

::

    PlanSource --action--> WaypointIk --reference--> split --+--> controller --> plant (arm)
        ^                      ^                             +--> plant (fingers, built-in PD)
        |                      +------- body_poses ------------------ plant
        +---- actions_done --- split

The dynamic layer is chosen by :attr:`RunConfig.mode`:

* ``torque`` - Drake's ``InverseDynamicsController`` (computed torque,
  tau = M(q)(a_d + Kp e + Kd e') + C(q, v)v + g(q)) on the 7-DOF control plant;
* ``position`` - the plant's built-in joint PD (implicit in SAP, so stable at 10 ms
  steps) on the desired state, plus the feed-forward torque of the reference from
  Drake's ``InverseDynamics`` (gravity included): what a position-controlled robot's
  firmware, or PyBullet's position mode, does for you.

With :attr:`RunConfig.reference` set, a recorded ``trajectory.npz`` replaces the planner
and the IK (``TrajectorySource`` on a spline fit): the exercise's computed-torque replay.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.controllers import InverseDynamics, InverseDynamicsController
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import Demultiplexer, LogVectorOutput, VectorLogSink

from cake_drake.dynamic.reference import ReferenceTrajectory
from cake_drake.errors import InputError
from cake_drake.geometric.collisions import CollisionChecker
from cake_drake.geometric.ik import Kinematics, make_solver
from cake_drake.geometric.solve import TimedSolver
from cake_drake.geometric.trajectory import Timing
from cake_drake.geometric.waypoints import WaypointParams
from cake_drake.symbolic import GroundAction
from cake_drake.systems.plan_source import PlanSource
from cake_drake.systems.waypoint_ik import WaypointIk
from cake_drake.world.scene import (
    Q_HOME,
    X_HAND_GRASP,
    Scene,
    WorldConfig,
    add_world,
    make_control_plant,
    set_default_cube_poses,
)

MODES = ("position", "torque")
#: Built-in joint PD gains of the position mode (N m/rad, N m s/rad).
POSITION_KP = (800.0, 800.0, 800.0, 800.0, 300.0, 200.0, 100.0)
POSITION_KD = (80.0, 80.0, 80.0, 80.0, 30.0, 20.0, 10.0)


@dataclass
class RunConfig:
    """Everything that shapes one run. CLI flags only fill these in."""

    mode: str = "torque"
    kp: float | Sequence[float] = 100.0  # torque mode, per joint (1/s^2)
    kd: float | Sequence[float] = 20.0  # torque mode, per joint (1/s)
    ik: str = "drake"
    seed: int = 0
    world: WorldConfig = field(default_factory=WorldConfig)
    timing: Timing = field(default_factory=Timing)
    waypoints: WaypointParams = field(default_factory=WaypointParams)
    check_collisions: bool = True  # report moves that sweep through cubes (warnings)
    avoid_collisions: bool = False  # raise the transit height until none is left
    reference: Path | None = None  # replay this trajectory.npz instead of planning motion
    differentiate: str = "spline"  # how the replay gets q-dot and q-double-dot

    def gains(self) -> tuple[np.ndarray, np.ndarray]:
        kp = np.broadcast_to(np.asarray(self.kp, float), (7,)).copy()
        kd = np.broadcast_to(np.asarray(self.kd, float), (7,)).copy()
        return kp, kd

    def check(self) -> None:
        if self.mode not in MODES:
            raise InputError(f"unknown mode {self.mode!r}; choose one of: {', '.join(MODES)}")
        try:
            kp, kd = self.gains()
        except ValueError:
            raise InputError("--kp/--kd take one value or seven (one per joint)") from None
        if np.any(kp <= 0) or np.any(kd < 0):
            raise InputError(f"gains must be kp > 0 and kd >= 0 (got kp={kp}, kd={kd})")


@dataclass
class CakeDiagram:
    """The built Diagram and handles to the parts a run reads."""

    diagram: Diagram
    scene: Scene
    config: RunConfig
    loggers: dict[str, VectorLogSink]
    plan_source: PlanSource | None = None
    waypoint_ik: WaypointIk | None = None
    reference: ReferenceTrajectory | None = None
    control_plant: object = None
    ik: TimedSolver | None = None
    visualizer: object = None  # MeshcatVisualizer, with --meshcat


def build_diagram(
    config: RunConfig,
    blocks: Sequence[str],
    initial_poses: Mapping[str, RigidTransform],
    actions: Sequence[GroundAction] = (),
    q_start: np.ndarray = Q_HOME,
    meshcat=None,
) -> CakeDiagram:
    """Wire planner, geometry and controller around the simulated Panda.

    ``meshcat`` (a ``pydrake.geometry.Meshcat``) adds a visualizer; never needed headless.
    """
    config.check()
    builder = DiagramBuilder()
    arm_gains = (POSITION_KP, POSITION_KD) if config.mode == "position" else None
    scene = add_world(builder, blocks, config.world, arm_gains=arm_gains)
    set_default_cube_poses(scene, initial_poses)
    plant = scene.plant
    plant.SetDefaultPositions(scene.arm, q_start)
    plant.SetDefaultPositions(scene.hand, [0.04, 0.04])
    dt = config.world.time_step
    control_plant = make_control_plant()

    # The reference: either the planner + waypoint/IK layers, or a recorded trajectory.
    plan_source = waypoint_ik = reference = solver = None
    if config.reference is None:
        plan_source = builder.AddNamedSystem("plan_source", PlanSource(actions))
        solver = TimedSolver(make_solver(config.ik, Kinematics(control_plant)))
        cube_bodies = {n: int(scene.cube_body(n).index()) for n in blocks}
        hand_body = int(plant.GetBodyByName("panda_hand", scene.hand).index())
        waypoint_ik = builder.AddNamedSystem(
            "waypoint_ik",
            WaypointIk(
                solver,
                q_start,
                cube_bodies,
                hand_body,
                X_HAND_GRASP,
                dt,
                config.timing,
                config.waypoints,
                config.world.slots,
                CollisionChecker(blocks) if config.check_collisions else None,
                config.avoid_collisions,
            ),
        )
        builder.Connect(plan_source.GetOutputPort("action"), waypoint_ik.GetInputPort("action"))
        builder.Connect(plant.get_body_poses_output_port(), waypoint_ik.GetInputPort("body_poses"))
        reference_port = waypoint_ik.GetOutputPort("reference")
    else:
        reference = ReferenceTrajectory.from_npz(config.reference, config.differentiate)
        source = builder.AddNamedSystem("reference", reference.make_source())
        reference_port = source.get_output_port()
    split = builder.AddNamedSystem("split_reference", Demultiplexer([14, 7, 4, 1, 2]))
    builder.Connect(reference_port, split.get_input_port())
    desired_state, desired_accel, fingers, done, labels = (
        split.get_output_port(i) for i in range(5)
    )
    if plan_source is not None:
        builder.Connect(done, plan_source.GetInputPort("actions_done"))
    builder.Connect(fingers, plant.get_desired_state_input_port(scene.hand))

    # The dynamic layer.
    arm_state = plant.get_state_output_port(scene.arm)
    loggers: dict[str, VectorLogSink] = {}
    if config.mode == "torque":
        kp, kd = config.gains()
        controller = builder.AddNamedSystem(
            "inverse_dynamics_controller",
            InverseDynamicsController(control_plant, kp, np.zeros(7), kd, True),
        )
        builder.Connect(arm_state, controller.get_input_port_estimated_state())
        builder.Connect(desired_state, controller.get_input_port_desired_state())
        builder.Connect(desired_accel, controller.get_input_port_desired_acceleration())
        builder.Connect(
            controller.get_output_port_control(), plant.get_actuation_input_port(scene.arm)
        )
        loggers["tau_commanded"] = LogVectorOutput(
            controller.get_output_port_control(), builder, dt
        )
    else:
        # Feed-forward: the torque the reference needs, M(q_d) a_d + C(q_d, v_d) v_d + g(q_d),
        # from Drake's InverseDynamics evaluated on the *desired* state; the PD corrects.
        feedforward = builder.AddNamedSystem(
            "feedforward",
            InverseDynamics(control_plant, InverseDynamics.InverseDynamicsMode.kInverseDynamics),
        )
        builder.Connect(desired_state, feedforward.get_input_port_estimated_state())
        builder.Connect(desired_accel, feedforward.get_input_port_desired_acceleration())
        builder.Connect(desired_state, plant.get_desired_state_input_port(scene.arm))
        builder.Connect(
            feedforward.get_output_port_generalized_force(),
            plant.get_actuation_input_port(scene.arm),
        )
        loggers["tau_commanded"] = LogVectorOutput(
            feedforward.get_output_port_generalized_force(), builder, dt
        )
    loggers["state"] = LogVectorOutput(arm_state, builder, dt)
    loggers["reference"] = LogVectorOutput(reference_port, builder, dt)
    loggers["tau_applied"] = LogVectorOutput(
        plant.get_net_actuation_output_port(scene.arm), builder, dt
    )
    for name, logger in loggers.items():
        logger.set_name(f"log_{name}")
    visualizer = None
    if meshcat is not None:
        from pydrake.visualization import AddDefaultVisualization

        AddDefaultVisualization(builder, meshcat)
        visualizer = meshcat
    diagram = builder.Build()
    diagram.set_name("cake_drake")
    return CakeDiagram(
        diagram,
        scene,
        config,
        loggers,
        plan_source,
        waypoint_ik,
        reference,
        control_plant,
        solver,
        visualizer,
    )
