"""The stage: a table, a Franka Panda at its edge and up to eight 4 cm cubes.

Everything is loaded from ``models/`` through Drake's ``PackageMap``: the package
``cake_drake`` is the repository's ``models/`` folder, and ``pybullet_franka_panda`` is the
Panda mesh folder that ships inside the ``pybullet`` wheel (installed from PyPI, never
downloaded at run time; the simulator itself is never imported).
"""

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.geometry import CollisionFilterDeclaration, GeometrySet, SceneGraph
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
from pydrake.multibody.tree import FixedOffsetFrame, ModelInstanceIndex, PdControllerGains
from pydrake.systems.framework import DiagramBuilder

from cake_drake import MODELS_DIR
from cake_drake.errors import InputError

CUBE_SIZE = 0.04  # m, edge of every cube
#: The coloured cube models in models/cubes (cube_<key>.sdf) and their colours. Blocks
#: take them in sorted order of their names: for a..e, block a is the red cube.
CUBE_COLOURS: dict[str, str] = {
    "a": "red",
    "b": "orange",
    "c": "yellow",
    "d": "green",
    "e": "blue",
    "f": "purple",
    "g": "cyan",
    "h": "pink",
}
ARM_JOINTS = tuple(f"panda_joint{i}" for i in range(1, 8))
FINGER_JOINTS = ("panda_finger_joint1", "panda_finger_joint2")
#: The grasp frame: between the fingertip pads, z pointing out of the hand.
X_HAND_GRASP = RigidTransform([0.0, 0.0, 0.1034])
#: A comfortable arm configuration above the table (hand pointing down).
Q_HOME = np.array([0.0, -0.3, 0.0, -2.2, 0.0, 1.9, math.pi / 4])
SCENE_DIRECTIVES = "package://cake_drake/scene/panda_on_table.dmd.yaml"
CONTROL_DIRECTIVES = "package://cake_drake/scene/panda_control.dmd.yaml"


SLOT_RADIUS = 0.55  # m from the robot base: where the Panda is dexterous pointing down


def make_slots(radius: float = SLOT_RADIUS) -> tuple[tuple[float, float], ...]:
    """Eight table slots on an arc of ``radius`` in front of the robot, 15 deg apart.

    Ordered centre-out (right of centre first), so that a few towers stand where the
    arm is most dexterous and the camera sees them all.
    """
    angles = [-7.5, 7.5, -22.5, 22.5, -37.5, 37.5, -52.5, 52.5]
    return tuple(
        (radius * math.cos(math.radians(a)), radius * math.sin(math.radians(a))) for a in angles
    )


#: (x, y) of each table slot, in the order towers are assigned to them.
SLOTS: tuple[tuple[float, float], ...] = make_slots()


@dataclass
class WorldConfig:
    """How the world is simulated. The defaults hold a stack of eight cubes at 10 ms steps.

    The ``world`` section of a :class:`cake_drake.scenario.Scenario`.
    """

    time_step: float = 0.01  # s, discrete MultibodyPlant step (SAP)
    #: SAP's near-rigid threshold: lower values regularise stiff contact less; 0.3-0.5
    #: keeps a tower from sagging at 10 ms steps, 1.0 (Drake's default) lets it sag ~5 mm.
    sap_near_rigid_threshold: float = 0.4
    contact_approximation: str = "sap"  # "lagged" (Drake's default) lets a tower slide apart
    finger_kp: float = 1000.0  # N/m; with the fingers commanded shut this squeezes ~20 N
    finger_kd: float = 20.0  # N s/m
    slot_radius: float = SLOT_RADIUS  # m: table slots on this arc around the base

    @property
    def slots(self) -> tuple[tuple[float, float], ...]:
        return make_slots(self.slot_radius)


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
    """Packages the models refer to: ``cake_drake`` and the Panda meshes (offline)."""
    import pybullet_data  # data only: the folder that holds franka_panda/meshes

    packages = PackageMap.MakeEmpty()
    packages.Add("cake_drake", str(MODELS_DIR))
    packages.Add("pybullet_franka_panda", str(Path(pybullet_data.getDataPath()) / "franka_panda"))
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


def cube_models(blocks: Sequence[str]) -> dict[str, str]:
    """Which cube model (key of :data:`CUBE_COLOURS`) each block gets: in sorted order."""
    if len(blocks) > len(CUBE_COLOURS):
        raise InputError(
            f"{len(blocks)} blocks, but the world has {len(CUBE_COLOURS)} cubes "
            f"({', '.join(CUBE_COLOURS.values())}): use at most {len(CUBE_COLOURS)} blocks"
        )
    return dict(zip(sorted(blocks), CUBE_COLOURS, strict=False))


def cube_directives(
    blocks: Sequence[str], poses: Mapping[str, RigidTransform] | None = None
) -> str:
    """Model directives that add one cube per block, named ``block_<name>``.

    Instances are named ``block_<name>`` so that a block may be called "table" or "hand";
    with ``poses`` each cube's ``default_free_body_pose`` is where it starts.
    """
    lines = ["directives:"]
    for name, key in cube_models(blocks).items():
        lines += [
            "- add_model:",
            f"    name: block_{name}",
            f"    file: package://cake_drake/cubes/cube_{key}.sdf",
        ]
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


def add_world(
    builder: DiagramBuilder,
    blocks: Sequence[str],
    config: WorldConfig = WorldConfig(),
    arm_gains: tuple[Sequence[float], Sequence[float]] | None = None,
    initial_poses: Mapping[str, RigidTransform] | None = None,
) -> Scene:
    """Add the plant (table, Panda, one cube per block name) and SceneGraph to ``builder``.

    The scene and the cubes are model directives (the cubes generated by
    :func:`cube_directives`, starting at ``initial_poses``). The plant is finalized here:
    the finger actuators are on the plant's implicit PD (stable at large time steps), and
    so are the arm's when ``arm_gains`` = (kp, kd) per joint is given (a controller that
    uses the built-in PD); the robot's own geometries never collide with each other.
    """
    plant_config = MultibodyPlantConfig(
        time_step=config.time_step,
        discrete_contact_approximation=config.contact_approximation,
        sap_near_rigid_threshold=config.sap_near_rigid_threshold,
        contact_model="point",
    )
    plant, scene_graph = AddMultibodyPlant(plant_config, builder)
    parser = make_parser(plant)
    _load_directives(parser, SCENE_DIRECTIVES)
    arm = plant.GetModelInstanceByName("panda")
    hand = plant.GetModelInstanceByName("hand")
    _add_grasp_frame(plant, hand)
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
    plant.Finalize()
    _filter_robot_collisions(plant, scene_graph, arm, hand)
    _filter_cube_collisions(plant, scene_graph, cubes)
    return Scene(plant, scene_graph, arm, hand, cubes)


#: The model's eight support spheres sit 8 mm in from the edges of the bottom and top
#: faces, reaching to those faces. :func:`_add_side_supports` gives the side faces the
#: same, recessed a little (x faces 0.5 mm, y faces 1 mm): with every face's spheres
#: reaching its plane, a cube rolling over an edge could come to rest balanced on it, on
#: the two rows of spheres either side; recessed by different amounts it always falls
#: onto the face whose spheres reach farthest.
_SUPPORT_IN = 0.012
_SIDE_REACH = (0.0175, 0.0170)  # sphere centres, x faces and y faces (radius 2 mm)


def _add_side_supports(plant: MultibodyPlant, body) -> None:
    """Support spheres for the four side faces (see :data:`_SIDE_REACH`).

    A cube knocked over lands on a side face; with spheres only on its top and bottom it
    would sink into the table to its spheres (6 mm) and read as resting on nothing.
    """
    from pydrake.geometry import ProximityProperties, Sphere
    from pydrake.multibody.plant import CoulombFriction

    props = ProximityProperties()  # the model's support spheres': mu 1, stiff, damped
    props.AddProperty("material", "coulomb_friction", CoulombFriction(1.0, 1.0))
    props.AddProperty("material", "point_contact_stiffness", 1e6)
    props.AddProperty("material", "hunt_crossley_dissipation", 5.0)
    # Edge spheres: a cube rolling over an edge would otherwise come to rest on the rows
    # of inset spheres either side of it, as on a chamfer; with a sphere on each edge it
    # balances on a line and falls onto a face, as a sharp-edged cube does. They touch
    # the table only (see _filter_cube_collisions), so stacking is unchanged.
    e = 0.018
    for i, (u, v) in enumerate(((0, 1), (0, 2), (1, 2))):
        for su in (-e, e):
            for sv in (-e, e):
                p = [0.0, 0.0, 0.0]
                p[u], p[v] = su, sv
                name = f"edge_{i}{int(su > 0)}{int(sv > 0)}"
                plant.RegisterCollisionGeometry(body, RigidTransform(p), Sphere(0.002), name, props)
    for axis, reach in enumerate(_SIDE_REACH):
        for sign in (-1.0, 1.0):
            for a in (-_SUPPORT_IN, _SUPPORT_IN):
                for b in (-_SUPPORT_IN, _SUPPORT_IN):
                    p = [a, a, b]
                    p[axis] = sign * reach
                    p[1 - axis] = a
                    name = f"corner_side_{axis}{int(sign > 0)}{int(a > 0)}{int(b > 0)}"
                    plant.RegisterCollisionGeometry(
                        body, RigidTransform(p), Sphere(0.002), name, props
                    )


def _filter_robot_collisions(plant, scene_graph, arm, hand) -> None:
    """The robot never collides with itself, and its base sits on the table."""
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


def _filter_cube_collisions(plant, scene_graph, cubes) -> None:
    """Cubes rest on each other and on the table through corner spheres only.

    Box-on-box point contact has a single, jumping contact point and lets a tower slide
    apart; ball-on-ball contact between two cubes' corners is unstable. So a cube's
    corner spheres touch only faces (another cube's box, the table, the finger pads touch
    the box), and boxes never touch boxes.
    """
    inspector = scene_graph.model_inspector()
    faces, corners, edges = GeometrySet(), GeometrySet(), GeometrySet()
    for instance in cubes.values():
        body = plant.GetBodyByName("cube", instance)
        for gid in plant.GetCollisionGeometriesForBody(body):
            name = inspector.GetName(gid).rsplit("::", 1)[-1]
            group = (
                corners
                if name.startswith("corner")
                else edges
                if name.startswith("edge")
                else faces
            )
            group.Add(gid)
    table = plant.GetBodyByName("table_top", plant.GetModelInstanceByName("table"))
    table_set = GeometrySet(plant.GetCollisionGeometriesForBody(table))
    manager = scene_graph.collision_filter_manager()
    manager.Apply(CollisionFilterDeclaration().ExcludeWithin(corners))
    manager.Apply(CollisionFilterDeclaration().ExcludeWithin(faces))
    manager.Apply(CollisionFilterDeclaration().ExcludeBetween(faces, table_set))
    # Edge spheres keep a fallen cube off its edges on the table and nothing else.
    manager.Apply(CollisionFilterDeclaration().ExcludeWithin(edges))
    manager.Apply(CollisionFilterDeclaration().ExcludeBetween(edges, faces))
    manager.Apply(CollisionFilterDeclaration().ExcludeBetween(edges, corners))


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


def layout(
    towers: Sequence[Sequence[str]], slots: Sequence[tuple[float, float]] = SLOTS
) -> dict[str, RigidTransform]:
    """World poses ``X_WB`` of every cube for towers given bottom to top, one slot each."""
    if len(towers) > len(slots):
        raise InputError(
            f"{len(towers)} towers need more table slots than the world has ({len(slots)})"
        )
    poses = {}
    for (x, y), tower in zip(slots, towers, strict=False):
        yaw = math.atan2(y, x)  # cube faces towards the robot
        for level, name in enumerate(tower):
            z = CUBE_SIZE / 2 + level * CUBE_SIZE
            poses[name] = RigidTransform(RollPitchYaw(0, 0, yaw), [x, y, z])
    return poses


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
