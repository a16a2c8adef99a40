"""Our two LeafSystems on their own: fixed inputs, evaluated outputs, as Drake tests systems."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.analysis import Simulator

from cake_drake.formats import PHASE_NAMES
from cake_drake.geometric.ik import Kinematics, make_solver
from cake_drake.geometric.trajectory import Timing
from cake_drake.geometric.waypoints import WaypointParams
from cake_drake.symbolic import GroundAction
from cake_drake.systems import ActionCommand, PlanSource
from cake_drake.systems.waypoint_ik import (
    REFERENCE_PORTS,
    MotionSettings,
    WaypointIk,
    WorldIndices,
)
from cake_drake.world.scene import Q_HOME, SLOTS, X_HAND_GRASP

PLAN = (GroundAction("unstack", ("a", "b")), GroundAction("put-down", ("a",)))


@pytest.mark.parametrize("done, expected", [(0, PLAN[0]), (1, PLAN[1]), (2, None)])
def test_plan_source_emits_the_action_after_those_done(done, expected):
    source = PlanSource(PLAN)
    context = source.CreateDefaultContext()
    source.GetInputPort("actions_done").FixValue(context, [done])
    command = source.GetOutputPort("action").Eval(context)
    assert command == ActionCommand(done, expected)


@pytest.fixture(scope="module")
def waypoint_ik():
    kin = Kinematics()
    world = WorldIndices(
        cube_bodies={"a": 1, "b": 2}, hand_body=0, X_hand_grasp=X_HAND_GRASP, slots=SLOTS
    )
    system = WaypointIk(
        make_solver("drake", kin),
        world,
        Q_HOME,
        kin.limits,
        0.01,
        MotionSettings(Timing(), WaypointParams()),
    )
    return system, kin


def _poses(kin: Kinematics) -> list[RigidTransform]:
    x, y = SLOTS[0]
    yaw = np.arctan2(y, x)
    X_hand = kin.pose(Q_HOME) @ X_HAND_GRASP.inverse()
    return [
        X_hand,
        RigidTransform(RollPitchYaw(0, 0, yaw), [x, y, 0.06]),  # a, on b
        RigidTransform(RollPitchYaw(0, 0, yaw), [x, y, 0.02]),  # b, on the table
    ]


def test_waypoint_ik_has_the_named_ports(waypoint_ik):
    system, _ = waypoint_ik
    for name, size in REFERENCE_PORTS.items():
        assert system.GetOutputPort(name).size() == size
    assert {system.get_input_port(i).get_name() for i in range(system.num_input_ports())} == {
        "action",
        "body_poses",
    }


def test_waypoint_ik_holds_the_start_until_an_action_comes(waypoint_ik):
    system, kin = waypoint_ik
    context = system.CreateDefaultContext()
    system.GetInputPort("action").FixValue(context, ActionCommand(0, None))
    system.GetInputPort("body_poses").FixValue(context, _poses(kin))
    np.testing.assert_array_equal(
        system.GetOutputPort("desired_state").Eval(context), np.r_[Q_HOME, np.zeros(7)]
    )
    np.testing.assert_array_equal(system.GetOutputPort("desired_acceleration").Eval(context), 0)
    assert system.GetOutputPort("actions_done").Eval(context)[0] == 0
    assert list(system.GetOutputPort("labels").Eval(context)) == [0, -1]


def test_waypoint_ik_executes_an_unstack_from_fixed_poses(waypoint_ik):
    system, kin = waypoint_ik
    context = system.CreateDefaultContext()
    system.GetInputPort("action").FixValue(context, ActionCommand(0, PLAN[0]))
    poses = _poses(kin)
    system.GetInputPort("body_poses").FixValue(context, poses)
    simulator = Simulator(system, context)
    seen_phases = set()
    for t in np.arange(0.05, 6.0, 0.05):
        simulator.AdvanceTo(t)
        phase, action = system.GetOutputPort("labels").Eval(context)
        seen_phases.add(PHASE_NAMES[int(phase)])
        if system.GetOutputPort("actions_done").Eval(context)[0] == 1:
            break
    assert system.GetOutputPort("actions_done").Eval(context)[0] == 1
    assert {"pre-grasp", "grasp", "lift"} <= seen_phases
    # Done once the lift may be blended into; at its end the arm is lifted above a, the
    # fingers commanded shut on it.
    end = system.progress(context).trajectory.end_time
    assert end > context.get_time()
    simulator.AdvanceTo(end)
    q = system.GetOutputPort("desired_state").Eval(context)[:7]
    X = kin.pose(q)
    np.testing.assert_allclose(X.translation()[:2], poses[1].translation()[:2], atol=1e-3)
    assert X.translation()[2] > poses[1].translation()[2] + 0.03
    assert system.GetOutputPort("finger_state").Eval(context)[0] == pytest.approx(0.0)
    assert system.progress(context).error is None


def _outcome(result) -> tuple:
    """Everything a run leaves, down to the bit: every log, the final poses and arm, what
    was executed and what the monitor recorded."""
    e = result.execution
    logs = {k: v.tobytes() for k, v in vars(e.logs).items() if v is not None}
    poses = {k: X.GetAsMatrix4().tobytes() for k, X in e.poses.items()}
    return logs, poses, e.q_final.tobytes(), e.actions, str(e.monitoring), e.error, e.sim_s


@pytest.mark.slow
def test_the_reference_tape_changes_no_bit_of_a_run(monkeypatch, tmp_path):
    """WaypointIk reads each step's reference from the tape made at the last decision;
    with no tape (every step's reference computed at that step) the runs are the same
    bit for bit: the exercise in both modes, a knocked cube with its replans, a
    generated problem."""
    from cake_drake.pipeline import run
    from cake_drake.scenario import Knock, Scenario, controller_for_mode
    from cake_drake.symbolic import random_problem
    from cake_drake.systems.waypoint_ik import Tape

    problem = tmp_path / "p6.pddl"
    problem.write_text(random_problem(6, seed=4))
    cases = []
    for mode, faults, task in [
        ("position", [], None),
        ("torque", [Knock("d", 1.0)], None),
        ("torque", [], str(problem)),
    ]:
        s = Scenario(controller=controller_for_mode(mode), faults=faults)
        if task is not None:
            s.task.problem = task
        cases.append(s)
    taped = [run(s, write=False) for s in cases]
    assert all(r.success for r in taped) and taped[1].execution.monitoring["replans"]
    untaped = np.array([], float)
    monkeypatch.setattr(WaypointIk, "_tape", lambda self, prog, t: Tape(0.01, 0, untaped, untaped))
    for s, with_tape in zip(cases, taped, strict=True):
        assert _outcome(run(s, write=False)) == _outcome(with_tape)


def test_a_smoothed_reference_is_continuous_and_settles_on_each_target():
    """A policy's or a skill's joint targets through the reference filter
    (``smooth_s``): position and velocity continuous when a new target comes, the
    velocity the position's derivative, and within 2 % of the target after ``smooth_s``."""
    from pydrake.systems.framework import LeafSystem

    from cake_drake.systems.waypoint_ik import declare_reference_ports, hold_target

    settle = 0.2
    targets = [np.full(7, 0.3)] * 3 + [np.full(7, -0.2)] * 3

    class Steps(LeafSystem):
        def __init__(self):
            super().__init__()
            self.groups = declare_reference_ports(self, np.zeros(7), settle)
            self.DeclarePeriodicUnrestrictedUpdateEvent(0.1, 0.0, self.update)

        def update(self, context, state):
            k = min(int(round(context.get_time() / 0.1)), len(targets) - 1)
            hold_target(self.groups, context, state, targets[k], settle)

    system = Steps()
    simulator = Simulator(system)
    context = simulator.get_mutable_context()
    port = system.GetOutputPort("desired_state")
    times = np.arange(0.0, 0.6, 0.002)
    rows = []
    for t in times:
        simulator.AdvanceTo(t)
        rows.append(port.Eval(context).copy())
    rows = np.array(rows)
    q, v = rows[:, 0], rows[:, 7]
    assert np.all(np.isfinite(rows))
    # No jump in position or velocity when a new target comes (at 0.3 s): 0.2 ms either
    # side, they differ by what the filter's acceleration (at most 6**2 / settle**2 times
    # the move) makes of 0.4 ms.
    simulator2 = Simulator(Steps())
    around = []
    for t in (0.2998, 0.3002):
        simulator2.AdvanceTo(t)
        around.append(simulator2.get_system().GetOutputPort("desired_state").Eval(
            simulator2.get_context()).copy())  # fmt: skip
    jump = np.abs(around[1] - around[0])
    assert np.all(jump[:7] < 1e-3) and np.all(jump[7:] < 900 * 0.5 * 4e-4 + 1e-3), jump
    # The velocity is the position's rate of change (away from the targets' times, where
    # the acceleration changes and a difference quotient is not the derivative).
    away = np.abs(times - np.round(times / 0.1) * 0.1) > 0.01
    assert np.allclose(np.gradient(q, times)[away], v[away], atol=0.05)
    # From rest, the first target is within 2 % of the move after smooth_s, and stays.
    at = np.searchsorted(times, settle)
    before = np.searchsorted(times, 0.3)
    assert np.all(np.abs(q[at:before] - 0.3) < 0.02 * 0.3), q[at:before]
    assert np.allclose(system.GetOutputPort("desired_acceleration").Eval(context), 0.0)
