"""From a symbolic action and the *measured* world to named Cartesian gripper poses.

Blocksworld splits one pick-and-place into two actions, so the six phases of the
exercise split between them:

* ``pick-up x`` / ``unstack x y`` (approach and grasp): **pre-grasp** (above x at the
  transit height), **grasp**
  (grasp frame at x's centre; the fingers close here), **lift** (straight up to the
  transit height);
* ``put-down x`` / ``stack x y`` (transport and place): **transport** (above the target at
  the transit height), **place** (x resting on the table slot or on y; the fingers open
  here), **retract** (straight up to the transit height).

All moves between actions thus happen at the transit height, which clears the tallest
tower by ``transit_clearance`` with a cube in the hand.

Every pose comes from measured poses: the grasp from x's pose, the place height from the
support's measured top, and the gripper pose at *place* from where the held cube
actually sits in the hand (so a cube that slipped is still set down where it belongs).
The gripper points down; its yaw follows the cube's yaw modulo 90 degrees, choosing the
turn nearest to the direction from the robot base (where the wrist is comfortable).

A cube lying tilted (dropped against another, say) is tilted about one of its axes, and
the two faces that axis leaves vertical can still be pinched from above: the fingers then
close along that axis (the yaw modulo 180 degrees). Set down, a cube that tilts in the
hand is released with its lowest corner where a flat cube's face would be, and falls flat.
"""

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from cake_drake.errors import ExecutionError
from cake_drake.symbolic import GroundAction
from cake_drake.world.facts import TILT_TOL, tilt
from cake_drake.world.scene import CUBE_SIZE, SLOTS

PICK_ACTIONS = ("pick-up", "unstack")
PLACE_ACTIONS = ("put-down", "stack")
#: A cube whose centre is farther than this from the grasp frame is not in the hand.
IN_HAND = 0.03  # m

PHASES = ("pre-grasp", "grasp", "lift", "transport", "place", "retract")


@dataclass
class WaypointParams:
    """Distances that shape the motion, metres (the ``motion.waypoints`` scenario section)."""

    approach: float = 0.06  # pre-grasp and retract: this far above grasp/place
    transit_clearance: float = 0.05  # held cube's bottom this far above every tower
    place_drop: float = 0.0005  # release the cube this far above its support
    #: The move down stops this much higher; there the hand's offset from its command is
    #: measured, and the last, short move takes it off and sets the cube down
    #: (:func:`cake_drake.geometric.solve.release_action`).
    release_height: float = 0.0015
    slot_clearance: float = 0.07  # a table slot is free if no cube is this close (xy)
    #: Quarter turns added to the comfortable gripper yaw. The hand is 20 cm wide along
    #: the fingers: turned a quarter, it reaches between towers that are close side by side.
    yaw_turns: int = 0


@dataclass(frozen=True)
class Waypoint:
    """One named gripper pose; ``gripper`` is the command *after* reaching it."""

    phase: str
    X_WG: RigidTransform
    gripper: str  # "open" or "closed"


@dataclass(frozen=True)
class WorldView:
    """What the geometric layer measures of the world at the start of an action."""

    cube_poses: Mapping[str, RigidTransform]
    X_WG: RigidTransform  # current gripper (grasp frame) pose
    held: str | None = None  # name of the cube in the hand, if any
    slots: tuple[tuple[float, float], ...] = SLOTS  # table slots (x, y) for put-down


def gripper_down(yaw: float) -> RotationMatrix:
    """Grasp-frame orientation pointing straight down, turned by ``yaw`` about world z."""
    return RotationMatrix.MakeZRotation(yaw) @ RotationMatrix.MakeXRotation(math.pi)


def face_yaw(X: RigidTransform) -> float:
    """The yaw of a cube's faces about world z, whichever face is down.

    A cube is symmetric: of its three axes, the one nearest to vertical says which face
    is down, and either of the other two gives the yaw (modulo 90 degrees).
    """
    R = X.rotation().matrix()
    down = int(np.argmax(np.abs(R[2, :])))
    side = R[:, (down + 1) % 3]
    return float(math.atan2(side[1], side[0]))


def grasp_yaw(X_WB: RigidTransform, preferred: float) -> float:
    """The gripper's yaw for picking the cube at ``X_WB``, nearest to ``preferred``: a
    quarter turn of its faces' yaw for a cube resting flat; for a tilted cube, the yaw at
    which the fingers (the grasp frame's y axis) close along the cube's axis nearest to
    horizontal, whose two faces stand vertical (a half turn of it)."""
    if tilt(X_WB) <= TILT_TOL:
        return nearest_turn(face_yaw(X_WB), preferred)
    R = X_WB.rotation().matrix()
    u = R[:, int(np.argmin(np.abs(R[2, :])))]
    # gripper_down(yaw)'s y axis is (sin yaw, -cos yaw, 0): along u at yaw(u) + 90 deg.
    yaw = math.atan2(u[1], u[0]) + math.pi / 2
    return yaw + round((preferred - yaw) / math.pi) * math.pi


def _lowest(X_WB: RigidTransform) -> float:
    """Height of the lowest corner of the cube at ``X_WB``."""
    R = X_WB.rotation().matrix()
    return float(X_WB.translation()[2] - CUBE_SIZE / 2 * np.sum(np.abs(R[2, :])))


def yaw_of(X: RigidTransform) -> float:
    """A frame's yaw about world z (rad): the hand's, a target's. The one place it is
    computed: the waypoints, the skills' observations and the hand-frame action space
    read it alike."""
    return float(RollPitchYaw(X.rotation()).yaw_angle())


def comfortable_yaw(p, params: WaypointParams) -> float:
    """The gripper's yaw over the point ``p`` that keeps the arm's wrist mid-range: the
    fingers across the line from the arm's base, turned by ``params.yaw_turns`` quarter
    turns. Grasps and places take the quarter turn of their cube nearest to it (the
    classical layer's, and a learned skill's: :class:`cake_drake.systems.skills.LearnedSkills`)."""
    return math.atan2(p[1], p[0]) + params.yaw_turns * math.pi / 2


def around_base(hand, destination, step: float) -> np.ndarray:
    """The point ``step`` (m) from ``hand`` on the way to ``destination`` (x y, world)
    around the arm's base: the bearing from the base and the distance from it change in
    proportion, as the classical layer's transit swings the arm about its first joint.
    The straight line between two towers on opposite sides of the table passes within a
    few centimetres of the base, where no top-down hand reaches; this way keeps to the
    arc the towers stand on. ``destination`` itself when it is no further than ``step``,
    or when either point is within 10 cm of the base (no bearing to keep)."""
    hand = np.asarray(hand, float)[:2]
    destination = np.asarray(destination, float)[:2]
    r0, r1 = float(np.hypot(*hand)), float(np.hypot(*destination))
    if np.hypot(*(destination - hand)) <= step or min(r0, r1) < 0.1:
        return destination
    a0 = math.atan2(hand[1], hand[0])
    turn = (math.atan2(destination[1], destination[0]) - a0 + math.pi) % (2 * math.pi) - math.pi
    s = np.linspace(0.0, 1.0, 257)[1:, None]
    way = (r0 + s * (r1 - r0)) * np.hstack([np.cos(a0 + s * turn), np.sin(a0 + s * turn)])
    return way[int(np.argmax(np.hypot(*(way - hand).T) >= step))]


def nearest_turn(yaw: float, preferred: float) -> float:
    """``yaw + k * 90 deg`` closest to ``preferred``."""
    k = round((preferred - yaw) / (math.pi / 2))
    return yaw + k * math.pi / 2


def transit_height(
    poses: Mapping[str, RigidTransform], held: str | None, params: WaypointParams
) -> float:
    """Grasp-frame height that carries a (held) cube clear of every tower."""
    tops = [X.translation()[2] + CUBE_SIZE / 2 for n, X in poses.items() if n != held]
    return max(tops, default=0.0) + CUBE_SIZE / 2 + params.transit_clearance


def free_slot(
    poses: Mapping[str, RigidTransform],
    held: str | None,
    params: WaypointParams,
    slots: Sequence[tuple[float, float]] = SLOTS,
) -> tuple[float, float]:
    """The first table slot with no cube near it (the held cube does not count)."""
    for x, y in slots:
        if all(
            np.hypot(X.translation()[0] - x, X.translation()[1] - y) > params.slot_clearance
            for n, X in poses.items()
            if n != held
        ):
            return x, y
    raise ExecutionError("put-down: every table slot is taken; the world has no free slot")


def waypoints_for(
    action: GroundAction, world: WorldView, params: WaypointParams = WaypointParams()
) -> list[Waypoint]:
    """The named gripper poses for ``action``, computed from ``world`` (see module doc)."""
    name, args = action.name, action.args
    poses = world.cube_poses
    missing = [a for a in args if a not in poses]
    if missing:
        raise ExecutionError(f"{action}: no cube named {missing[0]!r} in the world")
    block = args[0]
    if name in PICK_ACTIONS:
        X_WB = poses[block]
        p = X_WB.translation()
        preferred = comfortable_yaw(p, params)
        R = gripper_down(grasp_yaw(X_WB, preferred))
        z_transit = transit_height(poses, held=None, params=params)
        above = max(z_transit, p[2] + params.approach)
        return [
            Waypoint("pre-grasp", RigidTransform(R, [p[0], p[1], above]), "open"),
            Waypoint("grasp", RigidTransform(R, p), "closed"),
            Waypoint("lift", RigidTransform(R, [p[0], p[1], max(z_transit, p[2])]), "closed"),
        ]
    if name in PLACE_ACTIONS:
        if name == "stack":
            X_WS = poses[args[1]]
            target = X_WS.translation() + [0, 0, CUBE_SIZE + params.place_drop]
            target_yaw = face_yaw(X_WS)
        else:
            x, y = free_slot(poses, block, params, world.slots)
            target = np.array([x, y, CUBE_SIZE / 2 + params.place_drop])
            target_yaw = math.atan2(y, x)
        # Where the cube sits in the hand, measured now: X_GB = X_WG^-1 X_WB. A cube that is
        # not in the hand at all (it slipped, or someone took it) says nothing about the
        # grasp: the hand then goes through the motions with the nominal grasp, and the
        # world, measured after the action, shows what happened.
        X_GB = world.X_WG.inverse() @ poses[block]
        in_hand = np.linalg.norm(X_GB.translation()) < IN_HAND
        if not in_hand:
            X_GB = RigidTransform(RotationMatrix.MakeXRotation(math.pi), [0.0, 0.0, 0.0])
        # Cube yaw that is a quarter turn of the target's, with the gripper yaw nearest
        # to the comfortable one.
        preferred = comfortable_yaw(target, params)
        grip_minus_cube = yaw_of(world.X_WG) - face_yaw(poses[block]) if in_hand else 0.0
        cube_yaw = nearest_turn(target_yaw, preferred - grip_minus_cube)
        X_WB_target = RigidTransform(RotationMatrix.MakeZRotation(cube_yaw), target)
        X_place = X_WB_target @ X_GB.inverse()
        # Keep the gripper pointing straight down even if the cube tilted in the hand.
        R = gripper_down(yaw_of(X_place))
        X_place = RigidTransform(R, X_place.translation())
        # A cube tilted in the hand: released with its lowest corner where the flat cube's
        # face would be (it then falls flat), not pressed into its support.
        X_WB_held = X_place @ X_GB
        if in_hand and tilt(X_WB_held) > TILT_TOL:
            sink = (target[2] - CUBE_SIZE / 2) - _lowest(X_WB_held)
            X_place = RigidTransform(R, X_place.translation() + [0.0, 0.0, max(sink, 0.0)])
        z_transit = max(transit_height(poses, block, params), X_place.translation()[2])
        above = X_place.translation().copy()
        above[2] = z_transit
        # Up and clear of the tower just built - the transit height counting the cube
        # just placed - so the next move, which starts here, crosses nothing.
        z_after = target[2] + CUBE_SIZE + params.transit_clearance
        retract = X_place.translation().copy()
        retract[2] = max(z_transit, z_after, retract[2] + params.approach)
        return [
            Waypoint("transport", RigidTransform(R, above), "closed"),
            Waypoint("place", X_place, "open"),
            Waypoint("retract", RigidTransform(R, retract), "open"),
        ]
    raise ExecutionError(
        f"{action}: no waypoints for action {name!r}; the geometric layer knows "
        f"{', '.join(PICK_ACTIONS + PLACE_ACTIONS)}"
    )
