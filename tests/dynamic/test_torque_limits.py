"""Torque limits: every controller's torque is clamped to the Panda's 87 / 12 N m."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import BasicVector, LeafSystem

from cake_drake.diagram import build_diagram
from cake_drake.dynamic.controllers import TORQUE_LIMITS, JointPd
from cake_drake.execution import _logs
from cake_drake.pipeline import check, get_plan
from cake_drake.scenario import CustomController, Scenario
from cake_drake.symbolic import towers
from cake_drake.symbolic.roles import blocksworld_view
from cake_drake.world.scene import layout
from tests.helpers import ROOT

#: What a naive controller asks: far beyond every joint's limit.
ASKED = np.array([300.0, -300.0, 300.0, -300.0, 50.0, -50.0, 50.0])


class _Constant(LeafSystem):
    def __init__(self) -> None:
        super().__init__()
        self.DeclareVectorOutputPort("tau", BasicVector(7), lambda c, o: o.SetFromVector(ASKED))


class Overdriving:
    """A user's controller that commands 300 N m (it connects to the arm itself)."""

    name = "overdriving"

    def arm_pd_gains(self):
        return None

    def add_to(self, builder, scene, desired_state, desired_acceleration):
        source = builder.AddNamedSystem("constant_torque", _Constant())
        builder.Connect(source.get_output_port(), scene.plant.get_actuation_input_port(scene.arm))
        return source.get_output_port()


def make_overdriving() -> Overdriving:
    return Overdriving()


def simulate(scenario: Scenario, seconds: float = 0.1):
    checked = check(scenario, write=False)
    view = blocksworld_view(checked.problem)
    initial = layout(towers(view.init), scenario.world.slots_for(2))
    cake = build_diagram(scenario, checked.problem, initial, get_plan(checked).actions)
    sim = Simulator(cake.diagram)
    sim.AdvanceTo(seconds)
    return _logs(cake, sim.get_context())


def test_a_users_controller_is_clamped_and_the_saturation_reported():
    s = Scenario(controller=CustomController(factory=f"{__name__}:make_overdriving"))
    logs = simulate(s)
    limits = np.array(TORQUE_LIMITS)
    np.testing.assert_allclose(np.abs(logs.tau_applied[1:]), np.tile(limits, (len(logs.t) - 1, 1)))
    np.testing.assert_allclose(logs.tau_requested[-1], ASKED)
    sat = logs.saturation(TORQUE_LIMITS)
    assert sat["peak_nm"] == [300.0] * 4 + [50.0] * 3
    assert all(s >= 0.09 for s in sat["saturated_s"])


def test_pd_plus_gravity_lags_more_than_pd_with_feedforward():
    """!JointPd {feedforward: false}: PD on the error plus g(q) at the measured state, the
    drill's baseline; without the model of the motion it tracks worse, within limits."""
    baseline = simulate(Scenario(controller=JointPd(feedforward=False)), 0.3)
    full = simulate(Scenario(controller=JointPd()), 0.3)
    lag = np.max(np.abs(baseline.q - baseline.q_d))
    assert np.max(np.abs(full.q - full.q_d)) < lag < 0.1
    assert baseline.saturation(TORQUE_LIMITS)["saturated_s"] == [0.0] * 7
    # the feed-forward is gravity at the measured state: joints 2 and 4 carry the arm
    assert np.abs(baseline.tau_commanded[-1][[1, 3]]).min() > 1.0


def test_pid_at_the_default_step_is_refused_with_the_step_that_works():
    """The explicit PID's coupled fastest mode diverges at 10 ms: refused before simulating."""
    from cake_drake.dynamic.controllers import Pid
    from cake_drake.errors import InputError

    with pytest.raises(
        InputError, match=r"unstable at world.time_step 0.01 s: .* use world.time_step <= 0.00056"
    ):
        simulate(Scenario(controller=Pid()), 0.01)


def test_pid_holds_the_arm_at_half_a_millisecond_step():
    from cake_drake.dynamic.controllers import Pid

    s = Scenario(controller=Pid())
    s.world.time_step = 0.0005
    logs = simulate(s, 0.3)
    assert np.max(np.abs(logs.q - logs.q_d)) < 0.1
    assert logs.saturation(TORQUE_LIMITS)["saturated_s"] == [0.0] * 7


#: The command docs/drills.md shows for the PID (this test runs it for the doc tests).
PID_COMMAND = "python -m cake_drake.run --scenario models/scenarios/exercise.yaml --name pid"


@pytest.mark.slow
def test_the_pid_scenario_builds_the_tower_with_no_torque_at_a_limit(tmp_path):
    """The documented command, in a reader's checkout (40 s simulated at 0.5 ms steps)."""
    import shlex
    import shutil

    shutil.copytree(ROOT / "models", tmp_path / "models")
    argv = shlex.split(PID_COMMAND)
    r = subprocess.run([sys.executable, *argv[1:]], cwd=tmp_path, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "goal reached: a on b on c on d on e" in r.stdout
    summary = json.loads((tmp_path / "runs" / "pid" / "summary.json").read_text())
    assert summary["controller"]["name"] == "pid" and summary["events"] == []
    assert summary["torque_saturation"]["saturated_s"] == [0.0] * 7
    assert max(summary["stack_offsets_mm"].values()) < 1.0
    assert "warning" not in r.stderr
