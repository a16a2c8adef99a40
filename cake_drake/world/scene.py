"""The stage: a table, a Franka Panda at its edge and one 4 cm cube per block.

Everything is loaded from ``models/`` through Drake's ``PackageMap`` (the package
``cake_drake`` is the repository's ``models/`` folder); nothing is downloaded at run time.
"""

import colorsys
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from pydrake.geometry import (
    CollisionFilterDeclaration,
    GeometrySet,
    IllustrationProperties,
    PerceptionProperties,
    Rgba,
    Role,
    SceneGraph,
)
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.parsing import (
    LoadModelDirectives,
    PackageMap,
    Parser,
    ProcessModelDirectives,
)
from pydrake.multibody.plant import (
    AddMultibodyPlant,
    MultibodyPlant,
    MultibodyPlantConfig,
)
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    ModelInstanceIndex,
    PdControllerGains,
    SpatialInertia,
)
from pydrake.systems.framework import DiagramBuilder

from cake_drake.errors import InputError
from cake_drake.paths import MODELS_DIR, PACKAGE

CUBE_SIZE = 0.04  # m, edge of every cube
CUBE_MASS = 0.05  # kg, every cube's mass in models/cubes/cube.urdf
#: Every block is an instance of this one model; its colour is set per instance.
CUBE_MODEL = PACKAGE + "cubes/cube.urdf"
#: The first eight cube colours, by name (blocks take colours in natural order of their
#: names: for a..e, block a is the red cube). Further cubes take :func:`cube_colour`'s.
CUBE_COLOURS: dict[str, tuple[float, float, float]] = {
    "red": (0.85, 0.12, 0.12),
    "orange": (0.95, 0.55, 0.05),
    "yellow": (0.95, 0.85, 0.1),
    "green": (0.15, 0.7, 0.2),
    "blue": (0.12, 0.3, 0.9),
    "purple": (0.55, 0.2, 0.75),
    "cyan": (0.1, 0.8, 0.85),
    "pink": (0.95, 0.45, 0.7),
}
ARM_JOINTS = tuple(f"panda_joint{i}" for i in range(1, 8))
FINGER_JOINTS = ("panda_finger_joint1", "panda_finger_joint2")
#: The grasp frame: between the fingertip pads, z pointing out of the hand.
X_HAND_GRASP = RigidTransform([0.0, 0.0, 0.1034])
#: A comfortable arm configuration above the table (hand pointing down).
Q_HOME = np.array([0.0, -0.3, 0.0, -2.2, 0.0, 1.9, math.pi / 4])
SCENE_DIRECTIVES = PACKAGE + "scene/panda_on_table.dmd.yaml"
CONTROL_DIRECTIVES = PACKAGE + "scene/panda_control.dmd.yaml"


#: The table top (models/scene/table.urdf): x from -0.25 to 0.95 m, y within +-0.6 m.
TABLE_X = (-0.25, 0.95)
TABLE_HALF_WIDTH = 0.6
TABLE_MARGIN = 0.05  # m: a slot's centre stays this far inside the table's edges
#: m from the robot base. The Panda reaches every height a 10-high tower needs
#: (table to 0.56 m, gripper pointing down) out to 0.65 m (``benchmarks/reach.py``);
#: 0.55 m keeps 0.1 m of that in hand.
SLOT_RADIUS = 0.55
#: m between neighbouring slots, at least: the hand is 20 cm wide across its fingers,
#: which point along the arc, so 10 cm of hand plus 2 cm of cube plus 2.4 cm to spare.
SLOT_SPACING = 0.144
#: m between neighbouring slots, at most: a problem that needs few slots gets them
#: spread this far apart. Reaching the table 15 degrees clockwise of a tower 8 or more
#: high, the Panda's forearm (it hangs to that side) hits the tower; 17.5 degrees
#: clears a 10-high one. Few slots needed means few towers, and tall ones.
SLOT_SPACING_MAX = 0.2


def make_slots(
    radius: float = SLOT_RADIUS, spacing: float = SLOT_SPACING
) -> tuple[tuple[float, float], ...]:
    """Every table slot on the arc of ``radius`` around the base, ``spacing`` apart.

    The slots stand symmetrically about the x axis (half a step either side of it) and
    run out to the sides as far as the table reaches, in front of the base (x >= the
    margin); ordered centre-out, right of centre first, so that a few towers stand where
    the arm is most dexterous and the camera sees them all. At the defaults: 12 slots,
    15 degrees apart, from -82.5 to 82.5 degrees.
    """
    if radius <= 0 or spacing <= 0 or spacing >= 2 * radius:
        return ()
    step = 2 * math.asin(spacing / (2 * radius))  # chord of ``spacing``
    x_lo = max(TABLE_MARGIN, TABLE_X[0] + TABLE_MARGIN)
    x_hi = TABLE_X[1] - TABLE_MARGIN
    slots = []
    k = 0
    while (k + 0.5) * step <= math.pi / 2:
        for sign in (-1, 1):
            a = sign * (k + 0.5) * step
            x, y = radius * math.cos(a), radius * math.sin(a)
            if x_lo <= x <= x_hi and abs(y) <= TABLE_HALF_WIDTH - TABLE_MARGIN:
                slots.append((x, y))
        k += 1
    return tuple(slots)


#: (x, y) of each table slot at the defaults, in the order towers are assigned to them.
SLOTS: tuple[tuple[float, float], ...] = make_slots()


def spread_slots(
    count: int,
    radius: float = SLOT_RADIUS,
    spacing: float = SLOT_SPACING,
    spacing_max: float = SLOT_SPACING_MAX,
) -> tuple[tuple[float, float], ...]:
    """``count`` slots (or every slot, if the arc holds fewer) as far apart as the arc
    allows, between ``spacing`` and ``spacing_max`` apart.

    The widest spacing, in millimetre steps down from ``spacing_max``, at which
    :func:`make_slots` still finds ``count`` slots; never closer than ``spacing``.
    """
    wide = max(spacing, spacing_max)
    for k in range(int(round((wide - spacing) * 1000)) + 1):
        slots = make_slots(radius, wide - k / 1000)
        if len(slots) >= count:
            return slots[:count]
    return make_slots(radius, spacing)[: max(count, 0)]


@dataclass
class Placement:
    """Seeded variation of where the cubes start: each tower's place moved by up to ``xy``
    (m, in x and in y) and each cube turned about z by up to ``yaw_deg``, drawn from the
    run's seed. Towers never come closer than ``world.slot_spacing``; zeros (the default)
    keep the exercise's fixed slots."""

    xy: float = 0.0
    yaw_deg: float = 0.0


@dataclass
class WorldConfig:
    """How the world is simulated. The defaults hold a tower of ten cubes at 10 ms steps.

    The ``world`` section of a :class:`cake_drake.scenario.Scenario`.
    """

    time_step: float = 0.01  # s, discrete MultibodyPlant step (SAP)
    #: SAP's near-rigid threshold: lower values soften stiff contact less. A tower of
    #: cubes on corner spheres is an inverted pendulum on springs: at 0.4 a 10-high tower
    #: leans further with every cube and falls; 0.2 holds it (2.5 mrad at the top) at
    #: the same cost per step; below 0.2 SAP's answers turn erratic now and then (a
    #: laid-out tower blew apart at 0.1 and 0.15). docs/world.md has the measurements.
    sap_near_rigid_threshold: float = 0.2
    contact_approximation: str = "sap"  # "lagged" (Drake's default) lets a tower slide apart
    finger_kp: float = 1000.0  # N/m; with the fingers commanded shut this squeezes ~20 N
    finger_kd: float = 20.0  # N s/m
    slot_radius: float = SLOT_RADIUS  # m: table slots on this arc around the base
    slot_spacing: float = SLOT_SPACING  # m between neighbouring slots, at least
    slot_spacing_max: float = SLOT_SPACING_MAX  # m between them, at most (few slots needed)
    #: Seeded variation of the cubes' start (learning tasks): none by default.
    placement: Placement = field(default_factory=Placement)
    #: What the simulated world has and the controllers' model (the 7-DOF arm of
    #: :func:`make_control_plant`) lacks, on purpose: the cubes' true mass (kg; the model
    #: knows no cube at all), a payload rigidly at the grasp frame (kg), and viscous joint
    #: friction on the arm's seven joints (N m s/rad, one value or seven). The defaults are
    #: the world as it is (the URDFs' own values).
    cube_mass_kg: float = CUBE_MASS
    #: A range of the cubes' mass, ``[lo, hi]`` kg: each run draws one mass for all its
    #: cubes from its seed (uniform), in place of ``cube_mass_kg`` (empty: none). Learning
    #: tasks use it to show a skill every load; the same seed, the same mass.
    cube_mass_range_kg: list[float] = field(default_factory=list)
    payload_kg: float = 0.0
    joint_friction: list[float] = field(default_factory=lambda: [0.0])

    @property
    def slots(self) -> tuple[tuple[float, float], ...]:
        """Every slot the table holds, at the closest spacing (:func:`make_slots`)."""
        return make_slots(self.slot_radius, self.slot_spacing)

    def slots_for(self, count: int) -> tuple[tuple[float, float], ...]:
        """The ``count`` slots a problem needs, spread out (:func:`spread_slots`)."""
        return spread_slots(count, self.slot_radius, self.slot_spacing, self.slot_spacing_max)


@dataclass
class Scene:
    """Handles to the parts of a built world."""

    plant: MultibodyPlant
    scene_graph: SceneGraph
    arm: ModelInstanceIndex
    hand: ModelInstanceIndex
    cubes: dict[str, ModelInstanceIndex] = field(default_factory=dict)
    #: The 7-DOF arm model for controllers and IK (:func:`make_control_plant`).
    control_plant: MultibodyPlant | None = None

    @property
    def grasp_frame(self):
        return self.plant.GetFrameByName("grasp", self.hand)

    def cube_body(self, name: str):
        return self.plant.GetBodyByName("cube", self.cubes[name])


def package_map() -> PackageMap:
    """The one package the models refer to: ``cake_drake``, the ``models/`` folder
    (:data:`cake_drake.paths.PACKAGE`)."""
    packages = PackageMap.MakeEmpty()
    packages.Add("cake_drake", str(MODELS_DIR))
    return packages


def make_parser(plant: MultibodyPlant) -> Parser:
    parser = Parser(plant)
    parser.package_map().AddMap(package_map())
    return parser


def _load_directives(parser: Parser, url: str) -> None:
    path = parser.package_map().ResolveUrl(url)
    ProcessModelDirectives(LoadModelDirectives(path), parser)


def _add_grasp_frame(plant: MultibodyPlant, hand: ModelInstanceIndex) -> None:
    body_frame = plant.GetFrameByName("panda_hand", hand)
    plant.AddFrame(FixedOffsetFrame("grasp", body_frame, X_HAND_GRASP, hand))


def _natural(name: str) -> list:
    """Sort key that puts b2 before b10."""
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", name)]


def cube_colour(index: int) -> tuple[str, tuple[float, float, float]]:
    """(name, RGB) of the ``index``-th cube colour: the eight named ones, then darker
    shades whose hues step by the golden angle, so that any two stay apart."""
    named = list(CUBE_COLOURS.items())
    if index < len(named):
        return named[index]
    hue = (0.05 + 0.618034 * (index - len(named))) % 1.0
    return f"dark hue {round(hue * 360)}", colorsys.hsv_to_rgb(hue, 0.7, 0.55)


def cube_colours(blocks: Sequence[str]) -> dict[str, tuple[str, tuple[float, float, float]]]:
    """Each block's colour (name, RGB): in natural order of the names (b2 before b10)."""
    return {b: cube_colour(i) for i, b in enumerate(sorted(blocks, key=_natural))}


def cube_directives(
    blocks: Sequence[str], poses: Mapping[str, RigidTransform] | None = None
) -> str:
    """Model directives that add one cube per block, named ``block_<name>``.

    Instances are named ``block_<name>`` so that a block may be called "table" or "hand";
    with ``poses`` each cube's ``default_free_body_pose`` is where it starts.
    """
    lines = ["directives:"]
    for name in blocks:
        lines += ["- add_model:", f"    name: block_{name}", f"    file: {CUBE_MODEL}"]
        if poses is not None and name in poses:
            X = poses[name]
            rpy = np.degrees(RollPitchYaw(X.rotation()).vector())
            lines += [
                "    default_free_body_pose:",
                "      cube:",
                f"        translation: [{', '.join(repr(float(v)) for v in X.translation())}]",
                f"        rotation: !Rpy {{ deg: [{', '.join(repr(float(v)) for v in rpy)}] }}",
            ]
    return "\n".join(lines) + "\n" if len(lines) > 1 else "directives: []\n"


def _paint_cubes(plant: MultibodyPlant, scene_graph: SceneGraph, cubes) -> None:
    """Give every cube its colour (:func:`cube_colours`), for Meshcat and the camera."""
    inspector = scene_graph.model_inspector()
    source = plant.get_source_id()
    for name, (_, rgb) in cube_colours(list(cubes)).items():
        body = plant.GetBodyByName("cube", cubes[name])
        frame = plant.GetBodyFrameIdOrThrow(body.index())
        colour = Rgba(*rgb, 1.0)
        for gid in inspector.GetGeometries(frame, Role.kIllustration):
            illustration = IllustrationProperties(inspector.GetIllustrationProperties(gid))
            illustration.UpdateProperty("phong", "diffuse", colour)
            # Removed and assigned anew (kReplace warns that a visualizer may miss it).
            scene_graph.RemoveRole(source, gid, Role.kIllustration)
            scene_graph.AssignRole(source, gid, illustration)
        for gid in inspector.GetGeometries(frame, Role.kPerception):
            perception = PerceptionProperties(inspector.GetPerceptionProperties(gid))
            perception.UpdateProperty("phong", "diffuse", colour)
            scene_graph.RemoveRole(source, gid, Role.kPerception)
            scene_graph.AssignRole(source, gid, perception)


def add_world(
    builder: DiagramBuilder,
    blocks: Sequence[str],
    config: WorldConfig = WorldConfig(),
    arm_gains: tuple[Sequence[float], Sequence[float]] | None = None,
    initial_poses: Mapping[str, RigidTransform] | None = None,
    plant_and_scene_graph: tuple[MultibodyPlant, SceneGraph] | None = None,
    cube_boxes: bool = False,
) -> Scene:
    """Add the plant (table, Panda, one cube per block name) and SceneGraph to ``builder``
    (or fill ``plant_and_scene_graph``, a pair already in it, e.g. a ``RobotDiagramBuilder``'s).

    The scene and the cubes are model directives (the cubes generated by
    :func:`cube_directives`, starting at ``initial_poses``). The plant is finalized here:
    the finger actuators are on the plant's implicit PD (stable at large time steps), and
    so are the arm's when ``arm_gains`` = (kp, kd) per joint is given (a controller that
    uses the built-in PD); the robot's own geometries never collide with each other.
    With ``cube_boxes`` each cube is its bare box (no support spheres, no colour), as
    collision checking for motion planning wants it (:mod:`cake_drake.geometric.free_space`).
    """
    if plant_and_scene_graph is None:
        plant_config = MultibodyPlantConfig(
            time_step=config.time_step,
            discrete_contact_approximation=config.contact_approximation,
            sap_near_rigid_threshold=config.sap_near_rigid_threshold,
            contact_model="point",
        )
        plant, scene_graph = AddMultibodyPlant(plant_config, builder)
    else:
        plant, scene_graph = plant_and_scene_graph
    parser = make_parser(plant)
    _load_directives(parser, SCENE_DIRECTIVES)
    arm = plant.GetModelInstanceByName("panda")
    hand = plant.GetModelInstanceByName("hand")
    _add_grasp_frame(plant, hand)
    if cube_boxes:
        cubes = {name: _add_box_cube(plant, name) for name in blocks}
    else:
        parser.AddModelsFromString(cube_directives(blocks, initial_poses), "dmd.yaml")
        cubes = {name: plant.GetModelInstanceByName(f"block_{name}") for name in blocks}
        for instance in cubes.values():
            _add_side_supports(plant, plant.GetBodyByName("cube", instance))
    for joint_name in FINGER_JOINTS:
        actuator = plant.GetJointActuatorByName(f"{joint_name}_motor", hand)
        actuator.set_controller_gains(PdControllerGains(p=config.finger_kp, d=config.finger_kd))
    if arm_gains is not None:
        for i, (kp, kd) in enumerate(zip(*arm_gains, strict=True), start=1):
            actuator = plant.GetJointActuatorByName(f"panda_motor{i}", arm)
            actuator.set_controller_gains(PdControllerGains(p=kp, d=kd))
    _add_mismatch(plant, arm, hand, config)
    plant.Finalize()
    robot = _filter_robot_collisions(plant, scene_graph, arm, hand)
    if not cube_boxes:
        _paint_cubes(plant, scene_graph, cubes)
        _filter_cube_collisions(plant, scene_graph, cubes, robot)
    return Scene(plant, scene_graph, arm, hand, cubes)


def _add_mismatch(plant: MultibodyPlant, arm, hand, config: WorldConfig) -> None:
    """The payload and the joint friction of ``config`` (see :class:`WorldConfig`); the
    cubes' mass is a parameter of the context (:func:`set_world_parameters`)."""
    if config.payload_kg > 0:
        body = plant.AddRigidBody(
            "payload", hand, SpatialInertia.SolidBoxWithMass(config.payload_kg, 0.02, 0.02, 0.02)
        )
        plant.WeldFrames(plant.GetFrameByName("grasp", hand), body.body_frame())
    friction = [float(f) for f in config.joint_friction]
    if any(friction):
        friction = friction * 7 if len(friction) == 1 else friction
        for i, f in enumerate(friction, start=1):
            joint = plant.GetJointByName(f"panda_joint{i}", arm)
            joint.set_default_damping_vector(joint.default_damping_vector() + f)


def cube_mass(config: WorldConfig, seed: int) -> float:
    """The cubes' true mass in a run of ``seed``: ``cube_mass_kg``, or one drawn from
    ``cube_mass_range_kg`` by the seed (its own stream: the placement's draws stay as
    they were)."""
    if not config.cube_mass_range_kg:
        return float(config.cube_mass_kg)
    lo, hi = (float(m) for m in config.cube_mass_range_kg)
    return float(np.random.default_rng([int(seed) % 2**32, 7]).uniform(lo, hi))


def set_world_parameters(scene: Scene, plant_context, config: WorldConfig, seed: int = 0) -> None:
    """The cubes' true mass (:func:`cube_mass` of ``config`` and the run's ``seed``), set
    in ``plant_context`` (a body's mass is a parameter of the context): a solid 4 cm cube
    of that mass."""
    mass = cube_mass(config, seed)
    if mass == CUBE_MASS:
        return  # the URDF's own cube, untouched
    inertia = SpatialInertia.SolidBoxWithMass(mass, CUBE_SIZE, CUBE_SIZE, CUBE_SIZE)
    for instance in scene.cubes.values():
        body = scene.plant.GetBodyByName("cube", instance)
        body.SetSpatialInertiaInBodyFrame(plant_context, inertia)


def _add_box_cube(plant: MultibodyPlant, name: str) -> ModelInstanceIndex:
    """A free cube ``block_<name>`` that is only its box (see :func:`add_world`)."""
    from pydrake.geometry import Box
    from pydrake.multibody.plant import CoulombFriction

    instance = plant.AddModelInstance(f"block_{name}")
    inertia = SpatialInertia.SolidBoxWithMass(0.08, CUBE_SIZE, CUBE_SIZE, CUBE_SIZE)
    body = plant.AddRigidBody("cube", instance, inertia)
    box = Box(CUBE_SIZE, CUBE_SIZE, CUBE_SIZE)
    plant.RegisterCollisionGeometry(body, RigidTransform(), box, "box", CoulombFriction(1.0, 1.0))
    return instance


#: The model's eight support spheres sit 8 mm in from the edges of the bottom and top
#: faces, reaching to those faces. :func:`_add_side_supports` adds eight more at the
#: cube's corners, reaching 0.5 mm short of every face: they never touch while the cube
#: stands flat, carry it on whichever side face it is knocked onto, and on an edge they
#: are two contacts on a line, so the cube balances there no more than a real one does
#: and falls onto a face.
_CORNER_REACH = 0.0175  # m, corner sphere centres on each axis (radius 2 mm)


def _add_side_supports(plant: MultibodyPlant, body) -> None:
    """Corner spheres for the side faces and the edges (see :data:`_CORNER_REACH`).

    A cube knocked over lands on a side face; with spheres only on its top and bottom it
    would sink into the table to its spheres (6 mm) and read as resting on nothing.
    """
    from pydrake.geometry import ProximityProperties, Sphere
    from pydrake.multibody.plant import CoulombFriction

    props = ProximityProperties()  # the model's support spheres': mu 1, stiff, damped
    props.AddProperty("material", "coulomb_friction", CoulombFriction(1.0, 1.0))
    props.AddProperty("material", "point_contact_stiffness", 1e6)
    props.AddProperty("material", "hunt_crossley_dissipation", 5.0)
    e = _CORNER_REACH
    for x in (-e, e):
        for y in (-e, e):
            for z in (-e, e):
                name = f"corner_outer_{int(x > 0)}{int(y > 0)}{int(z > 0)}"
                plant.RegisterCollisionGeometry(
                    body, RigidTransform([x, y, z]), Sphere(0.002), name, props
                )


def _filter_robot_collisions(plant, scene_graph, arm, hand) -> GeometrySet:
    """The robot never collides with itself, and its base sits on the table. Returns
    the robot's collision geometries."""
    robot = GeometrySet()
    for instance in (arm, hand):
        for body_index in plant.GetBodyIndices(instance):
            robot.Add(plant.GetCollisionGeometriesForBody(plant.get_body(body_index)))
    base = GeometrySet(
        plant.GetCollisionGeometriesForBody(plant.GetBodyByName("panda_link0", arm))
        + plant.GetCollisionGeometriesForBody(plant.GetBodyByName("panda_link1", arm))
    )
    table = plant.GetModelInstanceByName("table")
    table_set = GeometrySet(
        plant.GetCollisionGeometriesForBody(plant.GetBodyByName("table_top", table))
    )
    manager = scene_graph.collision_filter_manager()
    manager.Apply(CollisionFilterDeclaration().ExcludeWithin(robot))
    manager.Apply(CollisionFilterDeclaration().ExcludeBetween(base, table_set))
    return robot


def _filter_cube_collisions(plant, scene_graph, cubes, robot: GeometrySet) -> None:
    """Cubes rest on each other and on the table through corner spheres only; the robot
    touches a cube's box only (the spheres lie within 0.5 mm of it).

    Box-on-box point contact has a single, jumping contact point and lets a tower slide
    apart; ball-on-ball contact between two cubes' corners is unstable. So a cube's
    corner spheres touch only faces (another cube's box, the table, the finger pads touch
    the box), and boxes never touch boxes.
    """
    inspector = scene_graph.model_inspector()
    faces, corners = GeometrySet(), GeometrySet()
    for instance in cubes.values():
        body = plant.GetBodyByName("cube", instance)
        for gid in plant.GetCollisionGeometriesForBody(body):
            name = inspector.GetName(gid).rsplit("::", 1)[-1]
            (corners if name.startswith("corner") else faces).Add(gid)
    table = plant.GetBodyByName("table_top", plant.GetModelInstanceByName("table"))
    table_set = GeometrySet(plant.GetCollisionGeometriesForBody(table))
    manager = scene_graph.collision_filter_manager()
    manager.Apply(CollisionFilterDeclaration().ExcludeWithin(corners))
    manager.Apply(CollisionFilterDeclaration().ExcludeWithin(faces))
    manager.Apply(CollisionFilterDeclaration().ExcludeBetween(faces, table_set))
    manager.Apply(CollisionFilterDeclaration().ExcludeBetween(corners, robot))


def make_control_plant(time_step: float = 0.0) -> MultibodyPlant:
    """The 7-DOF arm (hand welded on, fingers fixed) that ``InverseDynamicsController`` needs."""
    plant = MultibodyPlant(time_step)
    parser = make_parser(plant)
    _load_directives(parser, CONTROL_DIRECTIVES)
    hand = plant.GetModelInstanceByName("hand")
    _add_grasp_frame(plant, hand)
    plant.Finalize()
    return plant


# --- cube placement ------------------------------------------------------------------

#: m: every contact of a laid-out tower starts pressed this much. Laid out exactly
#: touching, SAP sees no contact in the first step: the whole tower falls at once, its
#: top sinks 20 mm in 0.2 s before it comes back, and a cube whose corner spheres sank
#: that deep into the one below can stay there. Pressed 0.05 mm, it settles by 0.1 mm.
LAYOUT_PRELOAD = 5e-5


def layout(
    towers: Sequence[Sequence[str]], slots: Sequence[tuple[float, float]] = SLOTS
) -> dict[str, RigidTransform]:
    """World poses ``X_WB`` of every cube for towers given bottom to top, one slot each."""
    if len(towers) > len(slots):
        raise InputError(
            f"{len(towers)} towers need more table slots than the table holds "
            f"({len(slots)} on the arm's arc: world.slot_radius, world.slot_spacing)"
        )
    poses = {}
    for (x, y), tower in zip(slots, towers, strict=False):
        yaw = math.atan2(y, x)  # cube faces towards the robot
        for level, name in enumerate(tower):
            z = CUBE_SIZE / 2 + level * CUBE_SIZE - (level + 1) * LAYOUT_PRELOAD
            poses[name] = RigidTransform(RollPitchYaw(0, 0, yaw), [x, y, z])
    return poses


def jittered(
    poses: Mapping[str, RigidTransform],
    towers: Sequence[Sequence[str]],
    placement: Placement,
    seed: int,
    spacing: float,
) -> dict[str, RigidTransform]:
    """``poses`` (from :func:`layout`) with each tower moved and each cube turned as
    ``placement`` says, drawn from ``seed``: the same seed, the same world. Towers keep at
    least ``spacing`` between their centres (redrawn until they do)."""
    if placement.xy == 0.0 and placement.yaw_deg == 0.0:
        return dict(poses)
    rng = np.random.default_rng([abs(int(seed)), 7919])
    bases = [np.asarray(poses[t[0]].translation()[:2]) for t in towers if t]
    for _ in range(1000):
        shift = rng.uniform(-placement.xy, placement.xy, size=(len(bases), 2))
        centres = [b + s for b, s in zip(bases, shift, strict=True)]
        if all(
            np.linalg.norm(centres[i] - centres[j]) >= spacing - 1e-9
            for i in range(len(centres))
            for j in range(i)
        ):
            break
    else:  # no draw kept the towers apart: keep the slots themselves
        shift = np.zeros((len(bases), 2))
    out = dict(poses)
    for tower, (dx, dy) in zip([t for t in towers if t], shift, strict=True):
        for name in tower:
            X = poses[name]
            yaw = math.radians(rng.uniform(-placement.yaw_deg, placement.yaw_deg))
            R = RollPitchYaw(0, 0, yaw).ToRotationMatrix().multiply(X.rotation())
            out[name] = RigidTransform(R, X.translation() + [dx, dy, 0.0])
    return out


def set_cube_poses(scene: Scene, context, poses: Mapping[str, RigidTransform]) -> None:
    """Place cubes (``context`` is the plant's context)."""
    for name, X_WB in poses.items():
        scene.plant.SetFreeBodyPose(context, scene.cube_body(name), X_WB)


def cube_poses(scene: Scene, context) -> dict[str, RigidTransform]:
    """Measured world poses of every cube (``context`` is the plant's context)."""
    return {
        name: scene.plant.EvalBodyPoseInWorld(context, scene.cube_body(name))
        for name in scene.cubes
    }


def set_arm_positions(scene: Scene, context, q: Sequence[float], fingers: float = 0.04) -> None:
    """Set the 7 arm joints and both fingers (opening per finger, m)."""
    scene.plant.SetPositions(context, scene.arm, np.asarray(q, dtype=float))
    scene.plant.SetPositions(context, scene.hand, [fingers, fingers])
