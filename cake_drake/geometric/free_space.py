"""The arm's free space among the cubes: Drake's ``SceneGraphCollisionChecker`` on the run's
own scene, the collision model of motion planning (:mod:`cake_drake.geometric.planners`).

:class:`FreeSpace` is built once per run from the same models as the simulation (the table,
the Panda and one cube per block) and then *set* for each move: the cubes where they are
measured, the cube in the hand (if any) attached to the hand as a box, and the robot allowed
to touch the cubes the action is about (the one it grasps or places and its support: that
contact is the action's purpose). A configuration is free when every robot body and every
attached box is at least ``padding`` from the cubes and the table.

Only the seven arm joints move in a query; the fingers and the cubes keep the pose the
move was set with. The checker's configurations are the whole plant's positions, so
:meth:`FreeSpace.full` writes the arm's seven angles into the set world's positions.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping, Sequence

import numpy as np
from pydrake.common import Parallelism
from pydrake.geometry import Box
from pydrake.math import RigidTransform
from pydrake.planning import RobotDiagramBuilder, SceneGraphCollisionChecker

from cake_drake.world.scene import CUBE_SIZE, WorldConfig, add_world

#: m, how far the robot and the cube it carries stay from everything else.
PADDING = 0.01
#: rad, the longest step between the configurations checked along a straight move.
RESOLUTION = 0.02
#: m, a carried cube is checked as a box this much smaller on every side: resting on the
#: table or a cube, a cube's faces touch its support (it stands on spheres that reach them).
HELD_SHRINK = 0.001
#: Where a held cube's own body is parked while its box rides on the hand.
_AWAY = RigidTransform([0.0, 0.0, -10.0])


class FreeSpace:
    """Collision queries for the arm among ``blocks``' cubes (see the module)."""

    def __init__(
        self, blocks: Sequence[str], padding: float = PADDING, resolution: float = RESOLUTION
    ) -> None:
        self.blocks = tuple(blocks)
        self.padding = padding
        self.resolution = resolution
        builder = RobotDiagramBuilder(time_step=0.0)
        scene = add_world(
            builder.builder(),
            list(blocks),
            WorldConfig(time_step=0.0),
            plant_and_scene_graph=(builder.plant(), builder.scene_graph()),
            cube_boxes=True,  # the spheres a cube stands on lie within its box
        )
        self.scene = scene
        quiet = logging.getLogger("drake")  # it announces the contexts it allocates
        level = quiet.level
        quiet.setLevel(logging.WARNING)
        try:
            self.checker = self._make_checker(builder, scene)
        finally:
            quiet.setLevel(level)
        plant = self.checker.plant()
        self._plant = plant
        self._context = plant.CreateDefaultContext()
        index = np.arange(plant.num_positions(), dtype=float)
        self._arm = plant.GetPositionsFromArray(scene.arm, index).astype(int)
        robot = (scene.arm, scene.hand)
        self._robot_bodies = [plant.get_body(b) for i in robot for b in plant.GetBodyIndices(i)]
        self._robot_indices = [int(b.index()) for b in self._robot_bodies]
        self._hand = plant.GetBodyByName("panda_hand", scene.hand)
        self._X_HG = plant.GetFrameByName("grasp", scene.hand).GetFixedPoseInBodyFrame()
        self._table = plant.GetBodyByName("table_top")
        # Copies: the getters return views of the checker's own matrices, which set() edits.
        self._nominal = np.array(self.checker.GetFilteredCollisionMatrix(), copy=True)
        self._padding = np.array(self.checker.GetPaddingMatrix(), copy=True)
        self._base = plant.GetPositions(self._context).copy()
        self.checks = 0  # configurations asked about, edges counted by their samples

    def _make_checker(self, builder, scene) -> SceneGraphCollisionChecker:
        return SceneGraphCollisionChecker(
            model=builder.Build(),
            robot_model_instances=[scene.arm, scene.hand],
            edge_step_size=self.resolution,
            env_collision_padding=self.padding,
            self_collision_padding=0.0,
            implicit_context_parallelism=Parallelism(1),
        )

    def set(
        self,
        cube_poses: Mapping[str, RigidTransform],
        fingers: float,
        held: str | None = None,
        X_GB: RigidTransform | None = None,
        touching: Iterable[str] = (),
    ) -> None:
        """The world of the next queries: cubes at ``cube_poses``, each finger opened
        ``fingers`` (m), ``held`` riding in the hand at ``X_GB`` (the grasp frame's pose of
        it), and the robot free to touch the cubes named in ``touching``. When it may touch
        any, the move goes down to a cube or up from one: the robot (and the cube it
        carries) may then come as close as touching to the table (no padding), as a cube
        set down on it or taken from it does."""
        plant, ctx = self._plant, self._context
        checker = self.checker
        checker.RemoveAllAddedCollisionShapes()
        for name in self.blocks:
            pose = _AWAY if name == held else cube_poses[name]
            plant.SetFreeBodyPose(ctx, self.scene_cube(name), pose)
        plant.SetPositions(ctx, self.scene.hand, [fingers, fingers])
        if held is not None:
            X_HB = self._X_HG @ X_GB
            size = CUBE_SIZE - 2 * HELD_SHRINK
            checker.AddCollisionShapeToBody("held", self._hand, Box(size, size, size), X_HB)
        # One matrix each (setting pairs one by one costs ~2 ms a pair).
        touching = tuple(touching)
        filtered = self._nominal.copy()
        padding = self._padding.copy()
        robot = self._robot_indices
        for name in touching:
            j = int(self.scene_cube(name).index())
            filtered[robot, j] = filtered[j, robot] = 1
        if touching:
            t = int(self._table.index())
            padding[robot, t] = padding[t, robot] = 0.0
        checker.SetCollisionFilterMatrix(filtered)
        checker.SetPaddingMatrix(padding)
        self._base = plant.GetPositions(ctx).copy()

    def scene_cube(self, name: str):
        return self._plant.GetBodyByName("cube", self.scene.cubes[name])

    def full(self, q: np.ndarray) -> np.ndarray:
        """The plant's positions with the arm at ``q`` and the rest as :meth:`set` put it."""
        x = self._base.copy()
        x[self._arm] = q
        return x

    def is_free(self, q: np.ndarray) -> bool:
        """Whether the arm at ``q`` keeps ``padding`` from everything it may not touch."""
        self.checks += 1
        return bool(self.checker.CheckConfigCollisionFree(self.full(np.asarray(q, float))))

    def edge_is_free(self, q0: np.ndarray, q1: np.ndarray) -> bool:
        """Whether the straight joint-space move ``q0`` -> ``q1`` is free, checked every
        ``resolution`` rad (its ends included)."""
        q0, q1 = np.asarray(q0, float), np.asarray(q1, float)
        self.checks += max(2, int(np.ceil(np.linalg.norm(q1 - q0) / self.resolution)) + 1)
        return bool(self.checker.CheckEdgeCollisionFree(self.full(q0), self.full(q1)))

    def nearest_hit(self, q: np.ndarray) -> tuple[str, str, float] | None:
        """The robot body, what it comes nearest to and their distance (m; negative when
        they overlap) for the pair nearest to overlapping their padding, else None (a
        cube carried counts as the hand)."""
        clearance = self.checker.CalcRobotClearance(self.full(np.asarray(q, float)), self.padding)
        d = np.asarray(clearance.distances())
        if d.size == 0:
            return None
        k = int(np.argmin(d))
        if d[k] >= 0:  # the distances are less the pair's padding
            return None
        robot = self._plant.get_body(clearance.robot_indices()[k]).name()
        other = self._plant.get_body(clearance.other_indices()[k])
        name = other.name()
        for block, inst in self.scene.cubes.items():
            if other.model_instance() == inst:
                name = f"cube {block}"
        pad = self.checker.GetPaddingBetween(
            clearance.robot_indices()[k], clearance.other_indices()[k]
        )
        return robot, name, float(d[k] + pad)
