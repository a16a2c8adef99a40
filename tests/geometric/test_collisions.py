"""Collision check of joint-space moves: flags sweeps through towers, passes clear moves."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.math import RigidTransform

from cake_drake.errors import InputError
from cake_drake.geometric.collisions import CollisionChecker, action_collisions
from cake_drake.geometric.ik import DrakeIk, Kinematics
from cake_drake.geometric.waypoints import WorldView, gripper_down, waypoints_for
from cake_drake.symbolic import GroundAction
from cake_drake.world.scene import CUBE_SIZE, Q_HOME, SLOTS, layout

BLOCKS = ["a", "b", "c", "d", "e"]
# Towers in the two centre slots (-7.5 and +7.5 deg); slots 2 and 3 (-22.5, +22.5) are free.
POSES = layout([["a", "b"], ["c", "d", "e"]])


@pytest.fixture(scope="module")
def checker():
    return CollisionChecker(BLOCKS)


@pytest.fixture(scope="module")
def ik():
    return DrakeIk(Kinematics())


def above_slot(ik, slot: int, z: float, seed: np.ndarray) -> np.ndarray:
    x, y = SLOTS[slot]
    q = ik.solve(RigidTransform(gripper_down(math.atan2(y, x)), [x, y, z]), seed)
    assert q is not None
    return q


def test_low_sweep_through_the_neighbouring_towers_is_flagged(checker, ik):
    """From slot 2 to slot 3 at a cube's height, the hand crosses both centre towers."""
    q0 = above_slot(ik, 2, CUBE_SIZE / 2, Q_HOME)
    q1 = above_slot(ik, 3, CUBE_SIZE / 2, q0)
    found = checker.check_move(q0, q1, POSES)
    hit = {c.other for c in found}
    assert {"cube a", "cube c"} <= hit  # the bottom cube of each tower
    assert all(c.body.startswith("panda_") for c in found)
    assert all(0 < c.first <= c.fraction <= c.last < 1 and c.depth > 0 for c in found)
    # The tower at -7.5 deg is met before the one at +7.5 deg.
    first = {c.other: c.first for c in found}
    assert first["cube a"] < first["cube c"]
    assert "hits cube a" in str(next(c for c in found if c.other == "cube a"))


def test_the_same_move_at_transit_height_is_clear(checker, ik):
    q0 = above_slot(ik, 2, 0.25, Q_HOME)
    q1 = above_slot(ik, 3, 0.25, q0)
    assert checker.check_move(q0, q1, POSES) == []


def test_a_held_cube_swept_through_a_tower_is_flagged(ik):
    """At 0.135 m the hand alone clears the c-d-e tower (top 0.12 m); a held cube does not."""
    checker = CollisionChecker([*BLOCKS, "f"])
    poses = dict(POSES)
    q0 = above_slot(ik, 3, 0.135, Q_HOME)
    q1 = above_slot(ik, 0, 0.135, q0)
    poses["f"] = RigidTransform([*SLOTS[3], CUBE_SIZE / 2])  # on the table, not in the hand
    assert checker.check_move(q0, q1, poses) == []
    poses["f"] = ik.kin.pose(q0)  # now held, grasped at its centre
    found = checker.check_move(q0, q1, poses, held="f")
    assert [(c.body, c.other) for c in found] == [("cube f (held)", "cube e")]
    assert 0 < found[0].depth < 0.01


def test_ignored_and_held_cubes_are_not_reported(checker, ik):
    q0 = above_slot(ik, 2, CUBE_SIZE / 2, Q_HOME)
    q1 = above_slot(ik, 3, CUBE_SIZE / 2, q0)
    found = checker.check_move(q0, q1, POSES, ignore=("a", "b", "c", "d", "e"))
    assert found == []


def test_the_hand_below_the_table_top_hits_the_table(checker, ik):
    x, y = SLOTS[4]
    q0 = above_slot(ik, 4, 0.1, Q_HOME)
    q1 = ik.solve(RigidTransform(gripper_down(math.atan2(y, x)), [x, y, -0.02]), q0)
    found = checker.check_move(q0, q1, POSES)
    assert [c.other for c in found] == ["table"] * len(found) and found
    assert all(c.body != "panda_link0" for c in found)
    assert max(c.fraction for c in found) == 1.0  # deepest at the end of the move


def test_every_move_of_a_pick_and_place_is_clear(checker, ik):
    """unstack e d then stack e b, seen through action_collisions: no warnings."""
    kin = ik.kin
    poses = dict(POSES)
    q = Q_HOME.copy()
    world = WorldView(poses, kin.pose(q))
    unstack = GroundAction("unstack", ("e", "d"))
    wps = waypoints_for(unstack, world)
    sols = []
    for w in wps:
        sols.append(ik.solve(w.X_WG, sols[-1] if sols else q))
    assert action_collisions(checker, unstack, world, wps, q, sols) == []
    # After the lift: e in the hand where the grasp put it.
    X_GB = wps[1].X_WG.inverse() @ poses["e"]
    poses["e"] = wps[2].X_WG @ X_GB
    world = WorldView(poses, wps[2].X_WG, held="e")
    stack = GroundAction("stack", ("e", "b"))
    wps2 = waypoints_for(stack, world)
    sols2 = []
    for w in wps2:
        sols2.append(ik.solve(w.X_WG, sols2[-1] if sols2 else sols[-1]))
    assert action_collisions(checker, stack, world, wps2, sols[-1], sols2) == []


def test_action_collisions_names_the_phase(ik):
    """From an arm left low beside the towers, the straight move to a pick-up's pre-grasp
    clips them: the collisions come back labelled with that phase, the rest is clear."""
    checker = CollisionChecker([*BLOCKS, "f"])
    poses = dict(POSES)
    poses["f"] = RigidTransform(POSES["a"].rotation(), [*SLOTS[3], CUBE_SIZE / 2])
    q_low = above_slot(ik, 2, 0.03, Q_HOME)
    world = WorldView(poses, ik.kin.pose(q_low))
    pick = GroundAction("pick-up", ("f",))
    wps = waypoints_for(pick, world)
    sols = []
    for w in wps:
        sols.append(ik.solve(w.X_WG, sols[-1] if sols else q_low))
    found = action_collisions(checker, pick, world, wps, q_low, sols)
    assert found and {phase for phase, _ in found} == {"pre-grasp"}
    assert {c.other for _, c in found} <= {"cube a", "cube b", "cube c", "cube d", "cube e"}
    # From above the towers instead, the same pick-up is clear.
    q_high = above_slot(ik, 2, 0.25, Q_HOME)
    world = WorldView(poses, ik.kin.pose(q_high))
    sols = []
    for w in wps:
        sols.append(ik.solve(w.X_WG, sols[-1] if sols else q_high))
    assert action_collisions(checker, pick, world, wps, q_high, sols) == []


def test_missing_cube_pose_is_an_input_error(checker):
    with pytest.raises(InputError, match="no pose for cube 'e'"):
        checker.check_move(Q_HOME, Q_HOME, {k: v for k, v in POSES.items() if k != "e"})
    with pytest.raises(InputError, match="held cube 'z'"):
        checker.check_move(Q_HOME, Q_HOME, POSES, held="z")


def test_samples_follow_the_largest_joint_motion(checker):
    assert checker.samples_for(Q_HOME, Q_HOME) == 2
    q1 = Q_HOME + np.array([0.5, 0, 0, 0, 0, 0, 0])
    assert checker.samples_for(Q_HOME, q1) == math.ceil(0.5 / checker.max_step) + 1
