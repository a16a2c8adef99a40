"""IK: round trips through forward kinematics, tolerances, determinism, named failures."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from cake_drake.errors import IkError, InputError
from cake_drake.geometric.ik import (
    ORIENTATION_TOL,
    POSITION_TOL,
    DlsIk,
    DrakeIk,
    Kinematics,
    make_solver,
)
from cake_drake.geometric.solve import solve_action
from cake_drake.geometric.trajectory import JointTrajectory
from cake_drake.geometric.waypoints import WorldView, gripper_down
from cake_drake.symbolic import GroundAction
from cake_drake.world.scene import Q_HOME, SLOTS


@pytest.fixture(scope="module")
def kin():
    return Kinematics()


def fk_errors(kin: Kinematics, q: np.ndarray, X: RigidTransform) -> tuple[float, float]:
    """(position error, rotation angle) of q against X, via Drake's own rotation algebra."""
    X_q = kin.pose(q)
    angle = (X_q.rotation().inverse() @ X.rotation()).ToAngleAxis().angle()
    return float(np.linalg.norm(X_q.translation() - X.translation())), abs(angle)


def tabletop_targets(n: int, seed: int = 3) -> list[RigidTransform]:
    """Gripper-down poses over the table slots' arc, at heights from a cube's centre up."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        r, a = rng.uniform(0.4, 0.7), rng.uniform(-1.0, 1.0)
        z, yaw = rng.uniform(0.02, 0.35), rng.uniform(-math.pi / 4, math.pi / 4)
        out.append(RigidTransform(gripper_down(a + yaw), [r * math.cos(a), r * math.sin(a), z]))
    return out


@pytest.mark.parametrize("solver_cls", [DrakeIk, DlsIk])
def test_round_trip_forward_kinematics_matches_target(kin, solver_cls):
    solver = solver_cls(kin)
    for X in tabletop_targets(25):
        q = solver.solve(X, Q_HOME)
        assert q is not None, f"{solver.name}: no solution for {X.translation()}"
        dp, dr = fk_errors(kin, q, X)
        assert dp <= POSITION_TOL and dr <= ORIENTATION_TOL
        assert np.all(q >= kin.lower) and np.all(q <= kin.upper)


def test_waypoint_chain_stays_on_the_seeds_branch(kin):
    """Seeded with the previous solution, a small move of the hand is a small joint move."""
    solver = DrakeIk(kin)
    x, y = SLOTS[0]
    yaw = math.atan2(y, x)
    q = solver.solve(RigidTransform(gripper_down(yaw), [x, y, 0.2]), Q_HOME)
    for z in (0.15, 0.1, 0.05, 0.02):
        q_next = solver.solve(RigidTransform(gripper_down(yaw), [x, y, z]), q)
        assert solver.last.stage == "seed"
        assert np.max(np.abs(q_next - q)) < 0.3
        q = q_next


def test_trac_ik_protocol_at_tight_tolerance(kin):
    """Random configurations -> pose -> solve from mid-limits, checked at 1e-5 m / 1e-5 rad."""
    solver = DrakeIk(kin, position_tol=1e-5, orientation_tol=1e-5)
    rng = np.random.default_rng(11)
    for _ in range(30):
        X = kin.pose(rng.uniform(kin.lower, kin.upper))
        q = solver.solve(X, kin.mid)
        assert q is not None
        dp, dr = fk_errors(kin, q, X)
        assert dp <= 1e-5 and dr <= 1e-5
        assert np.all(q >= kin.lower) and np.all(q <= kin.upper)


def test_tolerance_is_a_parameter_with_the_pipelines_default(kin):
    assert (DrakeIk(kin).position_tol, DrakeIk(kin).orientation_tol) == (1e-4, 1e-3)
    assert (DlsIk(kin).position_tol, DlsIk(kin).orientation_tol) == (1e-4, 1e-3)
    dls = DlsIk(kin)
    assert (dls.damping, dls.max_iterations) == (0.05, 200)
    # A loose answer is accepted at the default tolerance and refused at a tight one.
    X = tabletop_targets(1)[0]
    q = DrakeIk(kin).solve(X, Q_HOME)
    X_off = RigidTransform(X.rotation(), X.translation() + [3e-5, 0, 0])
    assert kin.within(q, X_off)
    assert not kin.within(q, X_off, position_tol=1e-5, orientation_tol=1e-5)


def test_drake_ik_is_deterministic(kin):
    """Same query, same answer: from one solver twice, and from a fresh solver."""
    rng = np.random.default_rng(5)
    targets = [kin.pose(rng.uniform(kin.lower, kin.upper)) for _ in range(10)]
    first = DrakeIk(kin, position_tol=1e-5, orientation_tol=1e-5)
    answers = [first.solve(X, kin.mid) for X in targets]
    again = [first.solve(X, kin.mid) for X in targets]
    fresh = DrakeIk(Kinematics(), position_tol=1e-5, orientation_tol=1e-5)
    other = [fresh.solve(X, kin.mid) for X in reversed(targets)][::-1]
    for a, b, c in zip(answers, again, other, strict=True):
        assert a is not None
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a, c)


def test_snopt_fallback_answers_when_newton_cannot_start(kin):
    """Without the Newton front end, InverseKinematics alone still finds the pose."""
    solver = DrakeIk(kin, newton_first=False, table_tries=0)
    X = tabletop_targets(1, seed=8)[0]
    q = solver.solve(X, Q_HOME)
    assert q is not None and solver.last.stage == "snopt" and solver.last.programs >= 1
    assert kin.within(q, X)


UNREACHABLE = RigidTransform(gripper_down(0.0), [1.5, 0.0, 0.1])  # 1.5 m away: beyond reach
#: 1.0 m from the shoulder: inside the chain-length bound (1.09 m), outside the real reach
#: (0.95 m), so every stage of DrakeIk runs and fails.
JUST_OUT_OF_REACH = RigidTransform(gripper_down(0.0), [1.0, 0.0, 0.333])


@pytest.mark.parametrize("name", ["drake", "dls"])
@pytest.mark.parametrize("X", [UNREACHABLE, JUST_OUT_OF_REACH], ids=["far", "just-out"])
def test_unreachable_pose_gives_none(kin, name, X):
    solver = make_solver(name, kin)
    assert solver.solve(X, Q_HOME) is None
    if name == "drake":
        assert solver.last.stage == "failed"
        assert kin.beyond_reach(X) == (X is UNREACHABLE)
        assert (solver.last.programs > 0) == (X is JUST_OUT_OF_REACH)


@pytest.mark.parametrize("name", ["drake", "dls"])
def test_unreachable_cube_raises_ik_error_naming_action_and_phase(kin, name):
    far = RigidTransform(RollPitchYaw(0, 0, 0), [1.5, 0.0, 0.02])
    world = WorldView({"a": far}, kin.pose(Q_HOME))
    action = GroundAction("pick-up", ("a",))
    with pytest.raises(IkError) as err:
        solve_action(action, 2, world, make_solver(name, kin), JointTrajectory(Q_HOME, kin.limits))
    message = str(err.value)
    assert "action 3 (pick-up a)" in message
    assert "pre-grasp" in message and "1.5" in message and name in message


def test_unknown_solver_lists_the_choices(kin):
    with pytest.raises(InputError, match="unknown IK solver 'trac'.*drake, dls"):
        make_solver("trac", kin)
