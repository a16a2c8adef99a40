"""Geometric feasibility of a move: does the arm sweep through a cube or the table?

The PDDLStream lesson: the symbolic planner knows nothing of geometry, so a plan it
finds can ask the arm to move through a neighbouring tower. :class:`CollisionChecker`
samples a straight joint-space move (the path of every move of
:class:`cake_drake.geometric.trajectory.JointTrajectory`; its timing does not change
the path), poses the arm, the fingers and the held cube at each sample, and asks
SceneGraph for penetrations between

* the robot (arm links, hand, finger pads) and every cube that is neither held nor
  named in ``ignore``;
* the robot, except its base links (``panda_link0``/``panda_link1``, bolted to the
  table), and the table;
* the held cube and every other cube not in ``ignore``, and the table.

Contacts between the robot and the held cube (the fingers squeeze it), between cubes
standing still and between cubes and the table are not reported, nor are penetrations
shallower than ``min_depth`` (a cube resting on its support touches it at depth ~0).

The checker owns its own plant and SceneGraph (built by
:func:`cake_drake.world.scene.add_world` with the simulation's collision filters), so
it can run beside a simulation without touching its context.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import CollisionFilterDeclaration, GeometrySet
from pydrake.math import RigidTransform
from pydrake.systems.framework import DiagramBuilder

from cake_drake.errors import InputError
from cake_drake.geometric.waypoints import PICK_ACTIONS, Waypoint, WorldView
from cake_drake.symbolic import GroundAction
from cake_drake.world.scene import CUBE_SIZE, Scene, WorldConfig, add_world

#: Finger opening (m per finger) while no cube is held: wide open.
FINGERS_OPEN = 0.04
#: ... and around a held cube: touching its faces.
FINGERS_HOLDING = CUBE_SIZE / 2
_BASE_LINKS = ("panda_link0", "panda_link1")


@dataclass(frozen=True)
class Collision:
    """The deepest penetration of one pair of bodies during a move.

    ``body`` is the moving one (a robot link such as ``panda_hand``, or ``cube b (held)``),
    ``other`` what it hits (``cube c`` or ``table``). ``fraction`` is where along the move
    it is deepest (0 = start, 1 = end; the path parameter, not time), ``depth`` how deep
    (m), ``first`` and ``last`` the first and last sampled fractions in contact.
    """

    body: str
    other: str
    fraction: float
    depth: float
    first: float
    last: float

    def __str__(self) -> str:
        span = (
            f"at {self.fraction:.0%} of the move"
            if self.first == self.last
            else f"from {self.first:.0%} to {self.last:.0%} of the move"
        )
        return f"{self.body} hits {self.other} {span} (up to {self.depth * 1000:.1f} mm deep)"


class CollisionChecker:
    """Checks straight joint-space moves of the Panda among the cubes ``blocks``.

    ``max_step`` (rad) bounds the joint motion between samples: 0.02 rad of joint 1 moves
    the hand ~1.2 cm at the slots' radius, well under a cube's 4 cm.

    By default the checker builds a world of its own. Given the ``scene`` of a Diagram
    being built, it checks in that world instead, in a context of its own, once
    :meth:`bind` has been given the built Diagram: the models are parsed once.
    """

    def __init__(
        self,
        blocks: Sequence[str],
        max_step: float = 0.02,
        min_depth: float = 5e-4,
        scene: Scene | None = None,
    ) -> None:
        self.blocks = tuple(blocks)
        self.max_step = max_step
        self.min_depth = min_depth
        self._context = None
        if scene is None:
            builder = DiagramBuilder()
            self.scene = add_world(builder, list(blocks), WorldConfig(time_step=0.0))
            self.bind(builder.Build())
        else:
            self.scene = scene

    def bind(self, diagram) -> None:
        """Check in ``diagram``, the built Diagram that holds :attr:`scene`."""
        scene = self.scene
        self._diagram = diagram
        self._context = diagram.CreateDefaultContext()
        plant, scene_graph = scene.plant, scene.scene_graph
        self._plant_context = plant.GetMyMutableContextFromRoot(self._context)
        self._sg_context = scene_graph.GetMyContextFromRoot(self._context)
        self._query_port = scene_graph.get_query_output_port()
        self._grasp = scene.grasp_frame
        # Every collision geometry -> (label, kind): kind is "robot", "base", "table" or
        # "cube", and for a cube the label is its block name.
        inspector = scene_graph.model_inspector()
        self._geometry: dict = {}
        robot_instances = (scene.arm, scene.hand)
        for gid in inspector.GetAllGeometryIds():
            body = plant.GetBodyFromFrameId(inspector.GetFrameId(gid))
            if body is None:
                continue
            if body.model_instance() in robot_instances:
                kind = "base" if body.name() in _BASE_LINKS else "robot"
                self._geometry[gid] = (body.name(), kind)
            elif body.name() == "table_top":
                self._geometry[gid] = ("table", "table")
        cubes_and_table = GeometrySet()
        for name, instance in scene.cubes.items():
            for gid in plant.GetCollisionGeometriesForBody(plant.GetBodyByName("cube", instance)):
                self._geometry[gid] = (name, "cube")
                cubes_and_table.Add(gid)
        cubes_and_table.Add([g for g, (_, kind) in self._geometry.items() if kind == "table"])
        # The simulation lets cubes touch each other and the table only through their
        # corner spheres (stable stacking); a held cube swept through a tower must show
        # with its whole box.
        sg_context = scene_graph.GetMyMutableContextFromRoot(self._context)
        scene_graph.collision_filter_manager(sg_context).Apply(
            CollisionFilterDeclaration().AllowWithin(cubes_and_table)
        )

    def samples_for(self, q0: np.ndarray, q1: np.ndarray) -> int:
        """Sampled configurations of the move q0 -> q1, both ends included."""
        step = float(np.max(np.abs(np.asarray(q1, float) - np.asarray(q0, float))))
        return max(2, math.ceil(step / self.max_step) + 1)

    def check_move(
        self,
        q0: np.ndarray,
        q1: np.ndarray,
        cube_poses: Mapping[str, RigidTransform],
        held: str | None = None,
        X_GB: RigidTransform | None = None,
        ignore: Iterable[str] = (),
        samples: int | None = None,
        fingers: float | None = None,
    ) -> list[Collision]:
        """Collisions of the straight joint-space move ``q0`` -> ``q1``, by first contact.

        ``cube_poses`` places every cube (``X_WB``); ``held`` names the cube in the hand,
        which rides rigidly at ``X_GB`` in the grasp frame (default: where
        ``cube_poses`` has it relative to the grasp frame at ``q0``). ``ignore`` names
        cubes whose contacts are expected (the one being grasped). ``samples`` overrides
        the count from ``max_step``; ``fingers`` the finger opening (m per finger).
        """
        if self._context is None:
            raise RuntimeError("CollisionChecker.bind() was not called with the built Diagram")
        missing = [b for b in self.blocks if b not in cube_poses]
        if missing:
            raise InputError(
                f"collision check: no pose for cube {missing[0]!r}; the checker's world has "
                f"cubes {', '.join(self.blocks)}"
            )
        if held is not None and held not in self.scene.cubes:
            raise InputError(
                f"collision check: held cube {held!r} is not one of {', '.join(self.blocks)}"
            )
        q0, q1 = np.asarray(q0, float), np.asarray(q1, float)
        plant, ctx = self.scene.plant, self._plant_context
        skip = set(ignore)
        if held is not None:
            skip.add(held)
        for name, X_WB in cube_poses.items():
            if name in self.scene.cubes:
                plant.SetFreeBodyPose(ctx, self.scene.cube_body(name), X_WB)
        if fingers is None:
            fingers = FINGERS_OPEN if held is None else FINGERS_HOLDING
        plant.SetPositions(ctx, self.scene.hand, [fingers, fingers])
        held_body = None
        if held is not None:
            held_body = self.scene.cube_body(held)
            if X_GB is None:
                plant.SetPositions(ctx, self.scene.arm, q0)
                X_GB = self._grasp.CalcPoseInWorld(ctx).inverse() @ cube_poses[held]
        n = samples if samples is not None else self.samples_for(q0, q1)
        found: dict[tuple[str, str], list] = {}  # pair -> [deepest, at, first, last]
        for k in range(n):
            s = k / (n - 1) if n > 1 else 0.0
            plant.SetPositions(ctx, self.scene.arm, q0 + s * (q1 - q0))
            if held_body is not None:
                X_WG = self._grasp.CalcPoseInWorld(ctx)
                plant.SetFreeBodyPose(ctx, held_body, X_WG @ X_GB)
            query = self._query_port.Eval(self._sg_context)
            for pair in query.ComputePointPairPenetration():
                if pair.depth < self.min_depth:
                    continue
                key = self._classify(pair.id_A, pair.id_B, held, skip)
                if key is None:
                    continue
                entry = found.get(key)
                if entry is None:
                    found[key] = [pair.depth, s, s, s]
                else:
                    if pair.depth > entry[0]:
                        entry[0], entry[1] = pair.depth, s
                    entry[3] = s
        out = [
            Collision(body, other, at, depth, first, last)
            for (body, other), (depth, at, first, last) in found.items()
        ]
        return sorted(out, key=lambda c: (c.first, c.body, c.other))

    def _classify(self, id_a, id_b, held: str | None, skip: set[str]) -> tuple[str, str] | None:
        """(moving body, what it hits) for a reportable pair, else None."""
        a, b = self._geometry.get(id_a), self._geometry.get(id_b)
        if a is None or b is None:
            return None
        for (name_m, kind_m), (name_o, kind_o) in ((a, b), (b, a)):
            if kind_m in ("robot", "base"):
                if kind_o == "cube" and name_o not in skip:
                    return name_m, f"cube {name_o}"
                if kind_o == "table" and kind_m == "robot":
                    return name_m, "table"
            elif kind_m == "cube" and name_m == held:
                if kind_o == "cube" and name_o not in skip:
                    return f"cube {held} (held)", f"cube {name_o}"
                if kind_o == "table":
                    return f"cube {held} (held)", "table"
        return None


def action_collisions(
    checker: CollisionChecker,
    action: GroundAction,
    world: WorldView,
    waypoints: Sequence[Waypoint],
    q_start: np.ndarray,
    solutions: Sequence[np.ndarray],
) -> list[tuple[str, Collision]]:
    """``(phase, collision)`` for every move of one action, in order.

    The moves run ``q_start`` -> ``solutions[0]`` -> ``solutions[1]`` ..., one per
    waypoint (the phase names the move's end). The cube the action moves rides in the
    hand from the waypoint where the fingers close (a pick's grasp) or from the start (a
    place, at the grasp ``world`` measures) until they open, and the place leaves it
    where the place waypoint sets it down. The action's own cubes (the one moved and its
    support or destination) are ignored: touching them is the action's purpose.
    """
    block = action.args[0]
    ignore = set(action.args)
    poses = dict(world.cube_poses)
    if action.name in PICK_ACTIONS:
        held, X_GB = None, None
    else:
        held, X_GB = block, world.X_WG.inverse() @ world.cube_poses[block]
    found = []
    q0 = np.asarray(q_start, float)
    for wp, q1 in zip(waypoints, solutions, strict=True):
        for c in checker.check_move(q0, q1, poses, held, X_GB, ignore):
            found.append((wp.phase, c))
        closing = wp.gripper == "closed" and held is None
        if closing:  # grasped here: the cube rides in the hand from now on
            held, X_GB = block, wp.X_WG.inverse() @ poses[block]
        elif wp.gripper == "open" and held is not None:  # let go: it stays where it is
            poses[block] = wp.X_WG @ X_GB
            held = X_GB = None
        q0 = np.asarray(q1, float)
    return found
