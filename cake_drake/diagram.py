"""Builds the whole cake as one Drake Diagram from a :class:`~cake_drake.scenario.Scenario`.

::

    action source --action--> WaypointIk --desired_state---------> controller --> plant (arm)
        ^                        ^    |     --desired_acceleration->
        |                        |    +----- finger_state ----------------------> plant (fingers)
        +---- actions_done ------|----+
                                 +-------- body_poses ------------------------- plant

The reference is either planned (an action source - the planner's plan by default -
feeding ``WaypointIk``) or a recorded ``trajectory.npz`` replayed through Drake's
``TrajectorySource``; both have the same named output ports, so the controller and the
loggers are wired the same way. :func:`_add_reference` is the one place that tells the
two apart, and :func:`cake_drake.dynamic.controllers.make_controller` the one place that
tells controllers apart. Nothing else in the project wires ports, except a controller,
which wires its own systems between the reference's ports and the arm's inputs.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.framework import Diagram, DiagramBuilder, System
from pydrake.systems.primitives import LogVectorOutput, VectorLogSink

from cake_drake import artifacts
from cake_drake.dynamic.controllers import (
    Controller,
    gravity_term,
    limit_torque,
    make_controller,
)
from cake_drake.dynamic.reference import ReferenceTrajectory
from cake_drake.geometric.collisions import CollisionChecker
from cake_drake.geometric.free_space import FreeSpace
from cake_drake.geometric.ik import Kinematics, make_solver
from cake_drake.geometric.planners import make_planner
from cake_drake.geometric.solve import Planning, TimedSolver
from cake_drake.paths import portable_path, resolve_path
from cake_drake.perception.estimator import CubeEstimator
from cake_drake.perception.learned import checkpoint_of, is_learned
from cake_drake.plugins import PluginError, is_plugin
from cake_drake.scenario import Policy, Recorded, Scenario
from cake_drake.symbolic import GroundAction, Problem
from cake_drake.symbolic.roles import blocksworld_roles, blocksworld_view
from cake_drake.systems import SourceContext, make_action_source
from cake_drake.systems.policy_source import PolicySource
from cake_drake.systems.skills import LearnedSkills
from cake_drake.systems.waypoint_ik import MotionSettings, WaypointIk, WorldIndices
from cake_drake.world.cameras import add_cameras
from cake_drake.world.faults import Knock, Pusher, Slip, SlipFingers
from cake_drake.world.scene import (
    Q_HOME,
    X_HAND_GRASP,
    Scene,
    add_world,
    cube_colours,
    make_control_plant,
)

#: The reference ports that are logged, with the arm's state and the torques.
LOGGED_REFERENCE_PORTS = ("desired_state", "desired_acceleration", "finger_state", "labels")


@dataclass
class ReferenceSource:
    """The system that produces the reference, and how to read the run's progress from it."""

    system: System  # has the named ports of cake_drake.systems.waypoint_ik.REFERENCE_PORTS
    actions: tuple[str, ...]  # the actions it executes, by name
    #: planned: the geometric layer (WaypointIk, or LearnedSkills: the same ports)
    geometric: WaypointIk | LearnedSkills | None = None
    action_source: System | None = None  # planned: where the actions come from
    replay: ReferenceTrajectory | None = None  # recorded: what is replayed
    policy: PolicySource | None = None  # a policy: the learned layer's slot

    def port(self, name: str):
        return self.system.GetOutputPort(name)

    def monitoring(self, root_context) -> dict:
        """What an execution monitor recorded: ``events``, ``replans``, ``checks`` (empty
        for an open-loop source); and with learned skills, ``skills``: how their actions
        ended (effects held, or budget ran out and handed back) and their steps."""
        found = {}
        source = self.action_source
        if source is not None and hasattr(source, "state"):
            s = source.state(source.GetMyContextFromRoot(root_context))
            found = {"events": list(s.events), "replans": s.replans, "checks": s.checks,
                     "places": [{"action": a, "offset_mm": round(o * 1000, 2)}
                                for a, o in s.places]}  # fmt: skip
        if isinstance(self.geometric, LearnedSkills):
            prog = self.geometric.progress(self.geometric.GetMyContextFromRoot(root_context))
            found["skills"] = {
                "checkpoint": self.geometric.label,
                "actions_ended": prog.done,
                "effects_held": prog.succeeded,
                "budget_ran_out": prog.ran_out,
                "stood_still": prog.stalled,
                "steps": prog.total_steps,
                "budget_steps": self.geometric.budget,
                "action_space": self.geometric.space,
                "clipped": self.geometric.counts.clipped,
                "unreachable": self.geometric.counts.unreachable,
                "shield": self.geometric.shield_summary(),
            }
        return found

    def executed(self, root_context) -> tuple[str, ...]:
        """The actions executed, by name, in order (an action source may have chosen them)."""
        source = self.action_source
        if source is not None and hasattr(source, "executed"):
            return tuple(str(a) for a in source.executed(source.GetMyContextFromRoot(root_context)))
        return self.actions

    def note(self, root_context) -> str:
        """What the geometric layer is doing, for the progress line: a learned skill's
        action under way and its steps in it (empty otherwise)."""
        if not isinstance(self.geometric, LearnedSkills):
            return ""
        prog = self.geometric.progress(self.geometric.GetMyContextFromRoot(root_context))
        if prog.working < 0:
            return ""
        return f"{prog.action}, skill step {prog.steps}/{self.geometric.budget}"

    def status(self, root_context) -> tuple[int, bool, str | None, tuple[str, ...]]:
        """(actions done, finished, the error that stopped execution or None, collision
        warnings). Planned: finished when the action source has no next action and the
        arm is idle; recorded: when every recorded action has run."""
        if self.policy is not None:
            return self.policy.steps, self.policy.finished(), None, ()
        if self.geometric is not None:
            prog = self.geometric.progress(self.geometric.GetMyContextFromRoot(root_context))
            source_context = self.action_source.GetMyContextFromRoot(root_context)
            command = self.action_source.GetOutputPort("action").Eval(source_context)
            # (a user's source may give anything: WaypointIk reports that as the error)
            finished = getattr(command, "action", 0) is None
            finished = finished and getattr(command, "index", None) == prog.done
            finished = finished and prog.working < 0
            error = prog.error
            if error is None and hasattr(self.action_source, "error"):
                error = self.action_source.error(source_context)
            return prog.done, finished, error, prog.warnings
        context = self.system.GetMyContextFromRoot(root_context)
        done = int(round(self.port("actions_done").Eval(context)[0]))
        return done, done >= len(self.actions), None, ()


@dataclass
class CakeDiagram:
    """The built Diagram and handles to the parts a run reads."""

    diagram: Diagram
    scene: Scene
    scenario: Scenario
    reference: ReferenceSource
    controller: Controller
    loggers: dict[str, VectorLogSink] = field(default_factory=dict)
    ik: TimedSolver | None = None
    cameras: dict = field(default_factory=dict)  # name -> RgbdSensor (cake_drake.world.cameras)
    #: The perception layer's system (None: the estimator is ``truth``).
    estimator: System | None = None


def _default_planner():
    from cake_drake.symbolic import DEFAULT_PLANNER, solve_problem

    return lambda problem, time_limit: solve_problem(problem, DEFAULT_PLANNER, time_limit)


def _add_reference(
    builder: DiagramBuilder,
    scenario: Scenario,
    scene: Scene,
    actions: Sequence[GroundAction],
    problem: Problem,
    q_start: np.ndarray,
    planner,
    slots: tuple[tuple[float, float], ...],
    cameras: dict,
    perceived,
    policy=None,
    skill=None,
) -> tuple[ReferenceSource, TimedSolver | None]:
    """The one place that tells a planned reference, a recorded one and a policy apart.
    ``perceived`` is the port every consumer reads the world's poses from (the plant's,
    or the perception layer's)."""
    ref = scenario.reference
    if isinstance(ref, Policy):
        return _add_policy(
            builder, scenario, scene, problem, q_start, slots, cameras, policy, len(actions),
            perceived,
        )  # fmt: skip
    if isinstance(ref, Recorded):
        replay = ReferenceTrajectory.from_npz(resolve_path(ref.path), ref.differentiate)
        system = builder.AddNamedSystem("reference", replay.make_source())
        return ReferenceSource(system, replay.executed_actions(), replay=replay), None
    plant = scene.plant
    indices = _world_indices(scene, slots)
    context = SourceContext(
        tuple(actions), problem, indices, planner, scenario.world.time_step, ref.max_replans,
        ref.re_place,
    )  # fmt: skip
    source = builder.AddNamedSystem("action_source", make_action_source(ref.action_source, context))
    roles = blocksworld_roles(problem.domain)
    meaning = lambda action: roles.classify(action).canonical()  # noqa: E731
    if scenario.motion.skills:
        geometric = _add_skills(builder, scenario, scene, indices, q_start, meaning, skill)
        solver = None
    else:
        geometric, solver = _add_waypoint_ik(
            builder, scenario, scene, indices, q_start, meaning, source.HasInputPort("infeasible")
        )
    builder.Connect(perceived, geometric.GetInputPort("body_poses"))
    wires = [
        (source.GetOutputPort("action"), geometric.GetInputPort("action")),
        (geometric.GetOutputPort("actions_done"), source.GetInputPort("actions_done")),
    ]
    if geometric.HasInputPort("arm_state"):
        wires.append((plant.get_state_output_port(scene.arm), geometric.GetInputPort("arm_state")))
        wires.append(
            (plant.get_state_output_port(scene.hand), geometric.GetInputPort("hand_state"))
        )
    if source.HasInputPort("body_poses"):
        wires.append((perceived, source.GetInputPort("body_poses")))
    if source.HasInputPort("infeasible"):
        wires.append((geometric.GetOutputPort("infeasible"), source.GetInputPort("infeasible")))
    if source.HasInputPort("hand_state"):
        wires.append((plant.get_state_output_port(scene.hand), source.GetInputPort("hand_state")))
    for out_port, in_port in wires:
        try:
            builder.Connect(out_port, in_port)
        except RuntimeError as e:  # a user's source whose ports are not the protocol's
            first = (str(e).strip().splitlines() or [""])[0]
            raise PluginError(
                f"action source {ref.action_source!r}: port {in_port.get_name()!r} or "
                f"{out_port.get_name()!r} does not fit the protocol ({first})"
            ) from None
    names = tuple(str(a) for a in actions)
    return ReferenceSource(geometric, names, geometric, source), solver


def _add_waypoint_ik(builder, scenario, scene, indices, q_start, meaning, feedback):
    """The classical geometric layer: waypoints, IK, timed moves (and its IK solver)."""
    kinematics = Kinematics(scene.control_plant)
    spec = scenario.motion.ik
    solver = TimedSolver(
        make_solver(spec, kinematics, scenario.seed),
        spec if is_plugin(spec) else None,
        (kinematics.lower, kinematics.upper),
    )
    motion = scenario.motion
    # Checks in the simulation's own world (bound once the Diagram is built).
    checker = CollisionChecker(list(scene.cubes), scene=scene) if motion.collision_check else None
    planning = None
    if motion.planner != "straight":
        planning = Planning(
            FreeSpace(list(scene.cubes)),
            make_planner(motion.planner),
            motion.planner,
            scenario.seed,
            (kinematics.lower, kinematics.upper),
        )
    settings = MotionSettings(
        motion.timing,
        motion.waypoints,
        checker,
        motion.avoid_collisions,
        meaning=meaning,
        planning=planning,
        feedback=feedback,
    )
    waypoint_ik = WaypointIk(
        solver, indices, q_start, kinematics.limits, scenario.world.time_step, settings
    )
    return builder.AddNamedSystem("waypoint_ik", waypoint_ik), solver


def _add_skills(builder, scenario, scene, indices, q_start, meaning, skill=None):
    """The learned geometric layer: a skill checkpoint executes each ground action
    (its adapter through the plug-in door: nothing here imports the learning code), or
    ``skill``, an object given (the skill environment's); a skill that answers moves of
    the hand gets the damped least squares a policy's ``ee_delta`` gets."""
    from cake_drake.geometric.ik import DlsIk
    from cake_drake.plugins import guarded, load_attribute
    from cake_drake.scenario import SKILL_POLICY
    from cake_drake.systems.skills import DEFAULT_BUDGET, LearnedSkills

    motion = scenario.motion
    label = portable_path(motion.skills)
    path = str(resolve_path(motion.skills))
    if skill is None:
        skill = guarded(f"skill {label!r}", load_attribute(SKILL_POLICY, "skill"), path,
                        motion.skill_device, motion.skill_ensemble)  # fmt: skip
    system = LearnedSkills(
        skill,
        label,
        indices,
        q_start,
        motion.skill_rate_hz,
        motion.skill_max_steps or DEFAULT_BUDGET,
        meaning,
        motion.waypoints,
        ik=DlsIk(Kinematics(scene.control_plant), max_iterations=50),
        smooth_s=motion.skill_smooth_s,
        rules=motion.skill_rules,
    )
    return builder.AddNamedSystem("skills", system)


def _world_indices(scene: Scene, slots) -> WorldIndices:
    plant = scene.plant
    return WorldIndices(
        cube_bodies={n: int(scene.cube_body(n).index()) for n in scene.cubes},
        hand_body=int(plant.GetBodyByName("panda_hand", scene.hand).index()),
        X_hand_grasp=X_HAND_GRASP,
        slots=slots,
    )


def _add_policy(
    builder, scenario, scene, problem, q_start, slots, cameras, policy, n_actions, perceived
):
    """A policy in place of the action source and WaypointIk (the learned layer's slot);
    its step budget scaled to the plan's ``n_actions`` unless the scenario sets one."""
    from cake_drake.geometric.ik import DlsIk
    from cake_drake.plugins import guarded
    from cake_drake.policy.observations import goal_facts, instruction
    from cake_drake.policy.spaces import step_budget
    from cake_drake.systems.policy_source import PolicyTask, make_policy, policy_of

    ref = scenario.reference
    view = blocksworld_view(problem)
    task = PolicyTask(
        instruction(view.goal),
        goal_facts(view.goal),
        tuple(view.blocks),
        problem,
        scenario,
        ref.action_space,
        ref.rate_hz,
        dict(ref.options),
    )
    kinematics = Kinematics(scene.control_plant)
    label = getattr(policy, "label", None) or (
        f"policy {ref.factory!r}" if ref.factory else "the policy"
    )
    if policy is None:
        factory, options = policy_of(ref)
        label = f"policy {ref.checkpoint!r}" if ref.checkpoint else label
        policy = make_policy(factory, options)
        guarded(label, policy.reset, task, scenario.seed)
    source = builder.AddNamedSystem(
        "policy",
        PolicySource(
            policy,
            label,
            ref.action_space,
            ref.options,
            ref.rate_hz,
            step_budget(ref.max_steps, n_actions, ref.rate_hz),  # in control periods
            _world_indices(scene, slots),
            DlsIk(kinematics, max_iterations=50),  # a step is small: Newton from the last
            (kinematics.lower, kinematics.upper),
            q_start,
            list(cameras),
            task,
            act_budget_s=ref.act_budget_s,
            smooth_s=ref.smooth_s,
        ),
    )
    plant = scene.plant
    builder.Connect(plant.get_state_output_port(scene.arm), source.GetInputPort("arm_state"))
    builder.Connect(plant.get_state_output_port(scene.hand), source.GetInputPort("hand_state"))
    builder.Connect(perceived, source.GetInputPort("body_poses"))
    for name, sensor in cameras.items():
        builder.Connect(sensor.color_image_output_port(), source.GetInputPort(f"image_{name}"))
    return ReferenceSource(source, (), policy=source), None


def build_diagram(
    scenario: Scenario,
    problem: Problem,
    initial_poses: Mapping[str, RigidTransform],
    actions: Sequence[GroundAction] = (),
    q_start: np.ndarray = Q_HOME,
    meshcat=None,
    planner=None,
    faults=(),
    slots: Sequence[tuple[float, float]] | None = None,
    policy=None,
    skill=None,
) -> CakeDiagram:
    """Wire the action source, geometry and controller around the simulated Panda, for
    ``problem``'s blocks starting at ``initial_poses`` and the planned ``actions``.

    ``meshcat`` (a ``pydrake.geometry.Meshcat``) adds a visualizer; never needed headless.
    ``planner`` is what an action source may replan with (default: the default planner).
    ``faults`` are resolved faults (:mod:`cake_drake.world.faults`): slips and knocks become
    systems here; moves happen in :func:`cake_drake.execution.execute`.
    ``slots`` are the table slots a put-down may use (default: every slot the scenario's
    world holds).
    ``policy`` is the object a ``!Policy`` reference asks, ``skill`` the object a scenario
    with ``motion.skills`` asks, in place of the checkpoint they name (the Gym envs').
    """
    controller = make_controller(scenario.controller)
    blocks = list(blocksworld_view(problem).blocks)
    builder = DiagramBuilder()
    scene = add_world(
        builder, blocks, scenario.world, controller.arm_pd_gains(), initial_poses=initial_poses
    )
    scene.control_plant = make_control_plant()
    plant = scene.plant
    plant.SetDefaultPositions(scene.arm, q_start)
    plant.SetDefaultPositions(scene.hand, [0.04, 0.04])

    slots = tuple(scenario.world.slots if slots is None else slots)
    cameras = add_cameras(builder, scene, scenario.cameras) if scenario.cameras else {}
    estimator = _add_perception(builder, scenario, scene)
    perceived = (
        plant.get_body_poses_output_port()
        if estimator is None
        else estimator.GetOutputPort("body_poses")
    )
    reference, solver = _add_reference(
        builder,
        scenario,
        scene,
        actions,
        problem,
        q_start,
        planner or _default_planner(),
        slots,
        cameras,
        perceived,
        policy,
        skill,
    )
    if estimator is not None and reference.action_source is not None:
        if reference.action_source.HasInputPort("cube_estimates"):
            builder.Connect(
                estimator.GetOutputPort("cube_estimates"),
                reference.action_source.GetInputPort("cube_estimates"),
            )
    finger_command = reference.port("finger_state")
    slips = [f.action for f in faults if isinstance(f, Slip)]
    if slips:
        slip = builder.AddNamedSystem("fault_slip", SlipFingers(slips))
        builder.Connect(finger_command, slip.GetInputPort("finger_state"))
        builder.Connect(reference.port("labels"), slip.GetInputPort("labels"))
        finger_command = slip.GetOutputPort("finger_command")
    builder.Connect(finger_command, plant.get_desired_state_input_port(scene.hand))
    pushes = [
        (int(scene.cube_body(f.cube).index()), f.time, f.duration, f.force)
        for f in faults
        if isinstance(f, Knock)
    ]
    if pushes:
        pusher = builder.AddNamedSystem("fault_knock", Pusher(pushes))
        builder.Connect(plant.get_body_poses_output_port(), pusher.GetInputPort("body_poses"))
        builder.Connect(
            pusher.GetOutputPort("forces"), plant.get_applied_spatial_force_input_port()
        )
    tau = controller.add_to(
        builder, scene, reference.port("desired_state"), reference.port("desired_acceleration")
    )
    requested = limit_torque(builder, scene) or tau

    dt = scenario.world.time_step
    loggers: dict[str, VectorLogSink] = {
        "state": LogVectorOutput(plant.get_state_output_port(scene.arm), builder, dt),
        "tau_commanded": LogVectorOutput(tau, builder, dt),
        "tau_applied": LogVectorOutput(plant.get_net_actuation_output_port(scene.arm), builder, dt),
        "tau_requested": LogVectorOutput(requested, builder, dt),
        # g(q) of the measured arm, for the joint plot: logged as the run goes (C++)
        # rather than computed row by row once it is over.
        "gravity": LogVectorOutput(gravity_term(builder, scene), builder, dt),
        # The fingers' measured state: whether the hand holds a cube (the residual's data).
        "hand": LogVectorOutput(plant.get_state_output_port(scene.hand), builder, dt),
    }
    for name in LOGGED_REFERENCE_PORTS:
        loggers[name] = LogVectorOutput(reference.port(name), builder, dt)
    if estimator is not None:  # the truth the estimates are measured against, afterwards
        for name, instance in scene.cubes.items():
            loggers[f"truth_{name}"] = LogVectorOutput(
                plant.get_state_output_port(instance), builder, dt
            )
    for name, logger in loggers.items():
        logger.set_name(f"log_{name}")
    if meshcat is not None:
        from cake_drake.outputs.replay import add_visualization

        add_visualization(builder, scene.scene_graph, meshcat)
    diagram = builder.Build()
    diagram.set_name("cake_drake")
    if reference.geometric is not None and reference.geometric.checker is not None:
        reference.geometric.checker.bind(diagram)
    return CakeDiagram(
        diagram, scene, scenario, reference, controller, loggers, solver, cameras, estimator
    )


def _add_perception(builder: DiagramBuilder, scenario: Scenario, scene: Scene):
    """The perception layer: None for ``truth`` (the plant's own port is read), else a
    ``CubeEstimator`` on its own cameras, fed the robot's measured joints."""
    perception = scenario.perception
    if perception.estimator == "truth":
        return None
    plant = scene.plant
    views = perception.views()
    sensors = add_cameras(builder, scene, views, prefix="perception_camera_")
    oracle = perception.estimator == "oracle"
    network = None
    if is_learned(perception.estimator):
        network = artifacts.load(checkpoint_of(perception.estimator), "perception",
                                 role="perception.estimator")  # fmt: skip
    cubes = {n: int(scene.cube_body(n).index()) for n in scene.cubes}
    colours = {n: rgb for n, (_, rgb) in cube_colours(list(scene.cubes)).items()}
    estimator = builder.AddNamedSystem(
        "perception",
        CubeEstimator(
            plant, scene.arm, scene.hand, cubes, colours, views, perception.noise,
            scenario.seed, perception.rate_hz, labels=cubes if oracle else None,
            network=network, keep_points=perception.keep_points,
        ),
    )  # fmt: skip
    builder.Connect(plant.get_state_output_port(scene.arm), estimator.GetInputPort("arm_state"))
    builder.Connect(plant.get_state_output_port(scene.hand), estimator.GetInputPort("hand_state"))
    for camera in views:
        sensor = sensors[camera.name]
        image = sensor.label_image_output_port() if oracle else sensor.color_image_output_port()
        kind = "label" if oracle else "color"
        builder.Connect(image, estimator.GetInputPort(f"{kind}_{camera.name}"))
        builder.Connect(
            sensor.depth_image_32F_output_port(), estimator.GetInputPort(f"depth_{camera.name}")
        )
    return estimator
