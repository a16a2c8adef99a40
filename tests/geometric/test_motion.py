"""The motion-planner slot: straight moves (the lesson), RRT-Connect (OMPL) on Drake's
collision checker, grasp and slot choice, and geometry that talks back to the plan."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pydrake.math import RigidTransform, RotationMatrix

from cake_drake.geometric.free_space import FreeSpace
from cake_drake.geometric.ik import Kinematics, make_solver
from cake_drake.geometric.planners import MoveQuery, ask, make_planner
from cake_drake.geometric.solve import Planning, solve_action
from cake_drake.geometric.trajectory import JointTrajectory
from cake_drake.geometric.waypoints import WorldView, gripper_down
from cake_drake.plugins import PluginError
from cake_drake.symbolic import GroundAction
from cake_drake.world.scene import Q_HOME
from tests.helpers import ROOT

CROWDED = ("--slot-radius", "0.4", "--slot-spacing", "0.104")

#: An IK solver that cannot reach the table's height (a stand-in for a place out of
#: reach): poses lower than 3 cm have no solution; with ``NORTH_ONLY`` only those south
#: of the base (y < 0) are refused.
REFUSING_IK = """
from cake_drake.geometric.ik import make_solver



def make(kinematics, seed):
    inner = make_solver("drake", kinematics, seed)

    class NoTable:
        name = "no-table"

        def solve(self, X_WG, q_seed):
            p = X_WG.translation()
            if p[2] < 0.03:
                return None
            return inner.solve(X_WG, q_seed)

    return NoTable()
"""

#: a on b, c beside: the goal (b clear, the hand empty) is one unstack and one put-down,
#: or one unstack and a stack on c.
CLEAR_B = """(define (problem clear-b) (:domain blocksworld) (:objects a b c)
  (:init (on a b) (on-table b) (on-table c) (clear a) (clear c) (arm-empty))
  (:goal (and {goal})))
"""


def cake(*args: str, cwd: Path, timeout: float = 600) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(cwd)])}
    return subprocess.run(
        [sys.executable, "-m", "cake_drake.run", *args],
        cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env,
    )  # fmt: skip


def summary(folder: Path) -> dict:
    return json.loads((folder / "summary.json").read_text())


@pytest.mark.slow
def test_on_a_tidy_table_rrt_connect_runs_bit_for_bit_the_straight_moves(tmp_path):
    for planner in ("straight", "rrt-connect"):
        r = cake("--motion-planner", planner, "--out", planner, cwd=tmp_path)
        assert r.returncode == 0, r.stderr
    straight, rrt = tmp_path / "straight", tmp_path / "rrt-connect"
    assert (straight / "trajectory.npz").read_bytes() == (rrt / "trajectory.npz").read_bytes()
    planned = summary(rrt)["motion_planner"]
    assert planned["name"] == "rrt-connect" and planned["queries"] == 0
    assert planned["collision_checks"] > 0  # every move was checked, none was blocked
    assert summary(straight)["motion_planner"] is None


@pytest.mark.slow
def test_the_crowded_table_knocks_with_straight_moves_and_builds_clean_with_rrt_connect(
    tmp_path,
):
    r = cake(*CROWDED, "--motion-planner", "straight", "--out", "straight", cwd=tmp_path)
    hits = summary(tmp_path / "straight")["collisions"]
    assert any("panda_hand hits cube" in h for h in hits), hits  # the exercise's lesson
    assert "warning: collision" in r.stderr
    r = cake(*CROWDED, "--motion-planner", "rrt-connect", "--out", "rrt", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    s = summary(tmp_path / "rrt")
    assert s["success"] and s["collisions"] == [], s["collisions"]
    assert s["stack_offsets_mm"] and max(s["stack_offsets_mm"].values()) < 3.0


def _blocked_query(seed: int = 7):
    """A low move from one side of a five-cube tower to the other."""
    blocks = list("abcde")
    poses = {n: RigidTransform([0.5, 0.0, 0.02 + 0.04 * i]) for i, n in enumerate(blocks)}
    space = FreeSpace(blocks)
    space.set(poses, 0.04)
    kin = Kinematics()
    ik = make_solver("drake", kin, 0)
    q0 = ik.solve(RigidTransform(gripper_down(0.0), [0.5, -0.15, 0.1]), Q_HOME)
    q1 = ik.solve(RigidTransform(gripper_down(0.0), [0.5, 0.15, 0.1]), Q_HOME)
    query = MoveQuery(q0, q1, space.is_free, kin.lower, kin.upper, seed, 5.0, space.resolution)
    return space, query


@pytest.mark.parametrize("spec", ["rrt-connect", "examples.via_point_planner:make"])
def test_a_planner_goes_around_a_tower_the_straight_move_goes_through(spec, monkeypatch):
    monkeypatch.chdir(ROOT)
    space, query = _blocked_query()
    assert space.is_free(query.start) and space.is_free(query.goal)
    assert not space.edge_is_free(query.start, query.goal)
    path = ask(make_planner(spec), spec, query)
    assert not isinstance(path, str), path
    assert np.array_equal(path[0], query.start) and np.array_equal(path[-1], query.goal)
    assert all(space.edge_is_free(a, b) for a, b in zip(path[:-1], path[1:], strict=True))
    again = ask(make_planner(spec), spec, query)
    assert np.array_equal(path, again)  # the same seed, the same path


def test_a_planner_plugin_that_returns_garbage_is_named(tmp_path, monkeypatch):
    (tmp_path / "bad_planner.py").write_text(
        "class Bad:\n    name = 'bad'\n    def plan(self, query):\n        return [[1, 2]]\n"
        "def make():\n    return Bad()\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    _, query = _blocked_query()
    with pytest.raises(PluginError, match=r"motion planner 'bad_planner:make' returned an array"):
        ask(make_planner("bad_planner:make"), "bad_planner:make", query)


def test_rrt_connect_without_ompl_is_refused_before_anything_runs(tmp_path):
    hide = tmp_path / "hide" / "ompl"
    hide.mkdir(parents=True)
    (hide / "__init__.py").write_text("raise ImportError('not installed here')\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path / "hide"), str(ROOT)])}
    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.run", "--motion-planner", "rrt-connect"],
        cwd=tmp_path, capture_output=True, text=True, timeout=120, env=env,
    )  # fmt: skip
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and "pip install" in r.stderr, r.stderr
    assert not (tmp_path / "outputs").exists()


def test_an_unknown_motion_planner_is_refused_with_the_choices(tmp_path):
    r = cake("--motion-planner", "prm", cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert "unknown motion planner 'prm'; choose one of: rrt-connect" in r.stderr


@pytest.mark.slow
def test_a_put_down_that_cannot_be_done_is_replanned_as_a_stack(tmp_path):
    (tmp_path / "no_table_ik.py").write_text(REFUSING_IK)
    (tmp_path / "p.pddl").write_text(CLEAR_B.format(goal="(clear b) (arm-empty)"))
    r = cake("--problem", "p.pddl", "--ik", "no_table_ik:make", "--out", "o", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    s = summary(tmp_path / "o")
    assert s["executed"] == ["(unstack a b)", "(stack a c)"]
    (event,) = s["events"]
    assert event["kind"] == "infeasible" and event["action"] == "(put-down a)"
    assert "no IK solution" in event["reason"] and event["new_plan"] == ["(stack a c)"]


@pytest.mark.slow
def test_an_action_no_plan_can_avoid_stops_the_run_naming_it(tmp_path):
    (tmp_path / "no_table_ik.py").write_text(REFUSING_IK)
    (tmp_path / "p.pddl").write_text(CLEAR_B.format(goal="(on-table a)"))
    r = cake("--problem", "p.pddl", "--ik", "no_table_ik:make", "--out", "o", cwd=tmp_path)
    assert r.returncode == 3, r.stderr
    line = r.stderr.strip().splitlines()[-1]
    assert "action 2 (put-down a): no IK solution" in line and "no plan avoids it" in line


def test_a_put_down_whose_first_slot_is_boxed_in_goes_to_the_next_free_one():
    """Two-high towers 7.5 cm from the first free slot on four sides: the hand at the place
    pose hits two of them at either turn; RRT-Connect's slot choice takes the next slot,
    straight moves take the first (and hit)."""
    kin = Kinematics()
    ik = make_solver("drake", kin, 0)
    first, second = (0.45, -0.2), (0.45, 0.2)
    poses = {}
    for k, (dx, dy) in enumerate([(0.075, 0), (-0.075, 0), (0, 0.075), (0, -0.075)]):
        for level in range(2):
            poses[f"n{k}{level}"] = RigidTransform(
                [first[0] + dx, first[1] + dy, 0.02 + 0.04 * level]
            )
    X_WG = RigidTransform(gripper_down(0.0), [0.45, 0.0, 0.3])
    poses["a"] = X_WG @ RigidTransform(RotationMatrix.MakeXRotation(np.pi), [0.0, 0.0, 0.0])
    world = WorldView(poses, X_WG, "a", (first, second))
    action = GroundAction("put-down", ("a",))
    q_start = ik.solve(X_WG, Q_HOME)
    places = {}
    for name in ("straight", "rrt-connect"):
        planning = None
        if name != "straight":
            planning = Planning(FreeSpace(sorted(poses)), make_planner(name), name, 0,
                                (kin.lower, kin.upper))  # fmt: skip
        motion = solve_action(action, 0, world, ik, JointTrajectory(q_start, kin.limits),
                              planning=planning)  # fmt: skip
        (place,) = [w for w in motion.waypoints if w.phase == "place"]
        places[name] = place.X_WG.translation()[:2]
    assert np.allclose(places["straight"], first, atol=0.01)
    assert np.allclose(places["rrt-connect"], second, atol=0.01)


@pytest.mark.parametrize("spec", ["rrt-connect", "examples.via_point_planner:make"])
def test_a_move_whose_goal_is_in_collision_is_the_layers_own_infeasibility(spec, monkeypatch):
    """A goal inside the tower (as a transit at zero clearance gives): no planner is asked
    and none is blamed; the reason is the layer's, fed back as an infeasible action."""
    from cake_drake.geometric.solve import _path

    monkeypatch.chdir(ROOT)
    space, query = _blocked_query()
    kin = Kinematics()
    inside = make_solver("drake", kin, 0).solve(
        RigidTransform(gripper_down(0.0), [0.5, 0.0, 0.1]), Q_HOME
    )
    assert not space.is_free(inside)
    planning = Planning(space, make_planner(spec), spec, 0, (kin.lower, kin.upper))
    for q0, q1, end in [(query.start, inside, "goal"), (inside, query.goal, "start")]:
        why = _path(planning, 0, "transport", q0, q1, 7)
        assert isinstance(why, str) and why.startswith(f"its {end} is not free"), why
    assert planning.queries == []  # the planner was not asked
