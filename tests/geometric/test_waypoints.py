"""Waypoints: the six phases from measured poses, for each Blocksworld action."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from cake_drake.errors import ExecutionError
from cake_drake.geometric.waypoints import (
    WaypointParams,
    WorldView,
    waypoints_for,
)
from cake_drake.symbolic import GroundAction
from cake_drake.world.scene import CUBE_SIZE, SLOTS, layout

PARAMS = WaypointParams()
X_HOME_G = RigidTransform(RollPitchYaw(math.pi, 0, 0), [0.3, 0.0, 0.4])


def yaw_of(X: RigidTransform) -> float:
    return float(RollPitchYaw(X.rotation()).yaw_angle())


def points_down(X: RigidTransform) -> bool:
    return np.allclose(X.rotation().col(2), [0, 0, -1], atol=1e-9)


def quarter_turns(angle: float) -> float:
    """How far ``angle`` is from a multiple of 90 degrees (rad)."""
    r = math.remainder(angle, math.pi / 2)
    return abs(r)


def holding(poses, block, X_WG_now, X_GB=None):
    """A world with ``block`` in the hand at ``X_GB`` (grasp frame at ``X_WG_now``)."""
    poses = dict(poses)
    poses[block] = X_WG_now @ (RigidTransform() if X_GB is None else X_GB)
    return WorldView(poses, X_WG_now, held=block)


def test_pick_up_phases_grasp_at_the_cube_centre_pointing_down():
    poses = layout([["a"], ["b", "c", "d"]])
    wps = waypoints_for(GroundAction("pick-up", ("a",)), WorldView(poses, X_HOME_G))
    assert [w.phase for w in wps] == ["pre-grasp", "grasp", "lift"]
    assert [w.gripper for w in wps] == ["open", "closed", "closed"]
    p = poses["a"].translation()
    np.testing.assert_allclose(wps[1].X_WG.translation(), p, atol=1e-12)
    tallest_top = poses["d"].translation()[2] + CUBE_SIZE / 2
    for w in wps:
        assert points_down(w.X_WG)
    for w in (wps[0], wps[2]):  # straight above the cube, clear of the tallest tower
        np.testing.assert_allclose(w.X_WG.translation()[:2], p[:2], atol=1e-12)
        assert w.X_WG.translation()[2] >= tallest_top + CUBE_SIZE / 2 + PARAMS.transit_clearance


@pytest.mark.parametrize("cube_yaw_deg", [0.0, 20.0, 65.0, 110.0, -150.0])
def test_unstack_gripper_yaw_follows_the_cube_modulo_90_degrees(cube_yaw_deg):
    poses = layout([["b", "a"]])
    X = poses["a"]
    poses["a"] = RigidTransform(RollPitchYaw(0, 0, math.radians(cube_yaw_deg)), X.translation())
    wps = waypoints_for(GroundAction("unstack", ("a", "b")), WorldView(poses, X_HOME_G))
    grasp = wps[1].X_WG
    assert quarter_turns(yaw_of(grasp) - math.radians(cube_yaw_deg)) < 1e-9
    # Of the four equivalent turns, the one nearest the direction from the robot base.
    x, y = X.translation()[:2]
    assert abs(math.remainder(yaw_of(grasp) - math.atan2(y, x), 2 * math.pi)) <= math.pi / 4
    np.testing.assert_allclose(grasp.translation(), X.translation(), atol=1e-12)
    # Lifted from a tower, the cube clears the other towers' tops.
    assert wps[2].X_WG.translation()[2] > X.translation()[2]


@pytest.mark.parametrize("tilt_deg, cube_yaw_deg", [(34.0, 0.0), (38.0, 25.0), (12.0, -70.0)])
def test_a_tilted_cube_is_pinched_by_the_two_faces_its_tilt_leaves_vertical(tilt_deg, cube_yaw_deg):
    """A cube dropped against another lies tilted about one axis: the fingers (the grasp
    frame's y axis) close along that axis, on the two faces that stand vertical."""
    poses = layout([["a"], ["b"]])
    p = poses["a"].translation() + [0.0, 0.0, 0.006]
    R = RotationMatrix.MakeZRotation(math.radians(cube_yaw_deg)) @ RotationMatrix.MakeXRotation(
        math.radians(tilt_deg)
    )
    poses["a"] = RigidTransform(R, p)
    axis = R.col(0)  # the tilt's axis: horizontal
    wps = waypoints_for(GroundAction("pick-up", ("a",)), WorldView(poses, X_HOME_G))
    grasp = wps[1].X_WG
    assert points_down(grasp)
    np.testing.assert_allclose(grasp.translation(), p, atol=1e-12)
    assert abs(abs(float(grasp.rotation().col(1) @ axis)) - 1.0) < 1e-9
    # The faces the fingers close on are vertical; the other pair is tilted.
    for k in (1, 2):
        assert abs(R.col(k)[2]) > 0.1
    # Of the two half turns, the one nearer the direction from the robot base.
    x, y = p[:2]
    assert abs(math.remainder(yaw_of(grasp) - math.atan2(y, x), 2 * math.pi)) <= math.pi / 2


def test_a_cube_tilted_in_the_hand_is_released_with_its_lowest_corner_at_the_table():
    poses = layout([["b"], ["a"]])
    X_GB = RigidTransform(RotationMatrix.MakeXRotation(math.pi + math.radians(30)), [0, 0, 0])
    world = holding(poses, "a", X_HOME_G, X_GB)
    place = waypoints_for(GroundAction("put-down", ("a",)), world)[1].X_WG
    held = place @ X_GB
    lowest = held.translation()[2] - CUBE_SIZE / 2 * np.sum(np.abs(held.rotation().matrix()[2]))
    assert lowest == pytest.approx(PARAMS.place_drop, abs=1e-9)  # not pressed into the table
    assert points_down(place)
    # A flat cube in the hand is set down as ever: its face place_drop above the table.
    flat = waypoints_for(GroundAction("put-down", ("a",)), holding(poses, "a", X_HOME_G))[1].X_WG
    assert flat.translation()[2] == pytest.approx(CUBE_SIZE / 2 + PARAMS.place_drop, abs=1e-9)


def test_stack_place_height_comes_from_the_supports_measured_top():
    """Support sagged 3 mm and turned 10 deg; the cube slipped 5 mm in the hand."""
    poses = layout([["b"], ["a"]])
    X_b = poses["b"]
    sagged = X_b.translation() - [0, 0, 0.003]
    poses["b"] = RigidTransform(RollPitchYaw(0, 0, yaw_of(X_b) + math.radians(10)), sagged)
    X_GB = RigidTransform(RotationMatrix.MakeXRotation(math.pi), [0.005, 0.0, 0.0])
    world = holding(poses, "a", X_HOME_G, X_GB)
    wps = waypoints_for(GroundAction("stack", ("a", "b")), world)
    assert [w.phase for w in wps] == ["transport", "place", "retract"]
    assert [w.gripper for w in wps] == ["closed", "open", "open"]
    cube_at_place = wps[1].X_WG @ X_GB
    expected = sagged + [0, 0, CUBE_SIZE + PARAMS.place_drop]
    np.testing.assert_allclose(cube_at_place.translation(), expected, atol=1e-9)
    # The placed cube lines up with its support modulo 90 degrees; the hand points down.
    assert quarter_turns(yaw_of(cube_at_place) - yaw_of(poses["b"])) < 1e-9
    assert all(points_down(w.X_WG) for w in wps)
    # Transport and retract are straight above the place pose.
    for w in (wps[0], wps[2]):
        np.testing.assert_allclose(
            w.X_WG.translation()[:2], wps[1].X_WG.translation()[:2], atol=1e-12
        )
        assert w.X_WG.translation()[2] > wps[1].X_WG.translation()[2]


def test_put_down_goes_to_the_first_free_slot_on_the_table():
    poses = layout([["b"], ["c", "d"]])  # slots 0 and 1 taken
    world = holding(poses, "a", X_HOME_G)
    wps = waypoints_for(GroundAction("put-down", ("a",)), world)
    cube_at_place = wps[1].X_WG  # X_GB is identity here
    np.testing.assert_allclose(cube_at_place.translation()[:2], SLOTS[2], atol=1e-9)
    assert cube_at_place.translation()[2] == pytest.approx(CUBE_SIZE / 2 + PARAMS.place_drop)
    # Carried clear of the tallest tower (c-d) with the cube's bottom above its top.
    top = poses["d"].translation()[2] + CUBE_SIZE / 2
    bottom_in_transport = wps[0].X_WG.translation()[2] - CUBE_SIZE / 2
    assert bottom_in_transport >= top + PARAMS.transit_clearance - 1e-12


def test_put_down_with_every_slot_taken_is_an_execution_error():
    names = [f"c{i}" for i in range(len(SLOTS))]
    poses = layout([[n] for n in names])
    world = holding(poses, "x", X_HOME_G)
    with pytest.raises(ExecutionError, match="every table slot is taken"):
        waypoints_for(GroundAction("put-down", ("x",)), world)


def test_missing_cube_and_unknown_action_are_named():
    world = WorldView(layout([["a"]]), X_HOME_G)
    with pytest.raises(ExecutionError, match="no cube named 'z'"):
        waypoints_for(GroundAction("pick-up", ("z",)), world)
    with pytest.raises(ExecutionError, match="no waypoints for action 'push'.*pick-up"):
        waypoints_for(GroundAction("push", ("a",)), world)
