"""Exercise 4.x.3's claims, checked from the logs of real replays through IDC."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from cake_drake.dynamic.analysis import settling, stationary_samples
from cake_drake.dynamic.controllers import JointPd
from cake_drake.formats import PHASE_NAMES
from cake_drake.gains import study
from cake_drake.outputs.report import gravity_torques
from cake_drake.pipeline import run
from cake_drake.scenario import Recorded, Scenario
from cake_drake.world.scene import make_control_plant

pytestmark = pytest.mark.slow
J4 = 3  # joint 4, zero-based


@pytest.fixture(scope="module")
def replays(tmp_path_factory):
    """The study's replays of a position run whose moves stop at every waypoint
    (``blend: 0``): the claims are about the moves themselves, and a blend would mix
    the end of one vertical move into the swing that follows it."""
    out = tmp_path_factory.mktemp("unblended")
    recorded = Scenario(controller=JointPd())
    recorded.motion.timing.blend = 0.0
    recorded.outputs.folder, recorded.outputs.render = str(out), False
    assert run(recorded).success
    base = Scenario(reference=Recorded(str(out / "trajectory.npz")))
    table, results = study(base, [20.0, 5.0])
    return table, results


def test_replay_builds_the_tower(replays):
    table, results = replays
    assert results[20.0].success, results[20.0].message
    assert table["runs"][0]["tower_built"] is True


def test_static_torque_is_the_gravity_term(replays):
    _, results = replays
    logs = results[20.0].logs
    still = stationary_samples(logs.v, logs.v_d)
    assert still.sum() > 20
    g = gravity_torques(make_control_plant(), logs.q[still])[:, J4]
    tau = logs.tau_commanded[still, J4]
    assert np.all(np.abs(g) > 1.0), "joint 4 carries a gravity load whenever the arm is still"
    rel = np.abs(tau - g) / np.abs(g)
    assert np.median(rel) < 0.01
    assert np.all(rel < 0.05), f"worst still sample differs from g(q) by {rel.max():.1%}"


def test_elbow_dynamic_torque_peaks_in_the_vertical_moves_not_the_swing(replays):
    _, results = replays
    logs = results[20.0].logs
    g = gravity_torques(make_control_plant(), logs.q)[:, J4]
    dynamic = np.abs(logs.tau_commanded[:, J4] - g)
    top = np.argsort(dynamic)[-10:]
    phases = {PHASE_NAMES[logs.phase[i]] for i in top}
    assert phases <= {"lift", "place", "retract"}, phases
    transport = logs.phase == PHASE_NAMES.index("transport")
    assert dynamic[transport].max() < 0.6 * dynamic.max()  # a swing about joint 1


def test_lower_kd_tracks_worse(replays):
    table, _ = replays
    kd20, kd5 = table["runs"]
    assert kd5["rms_tracking_error"][J4] > 1.2 * kd20["rms_tracking_error"][J4]
    assert max(kd5["max_tracking_error"]) > max(kd20["max_tracking_error"])


def test_overshoot_decays_within_half_a_second_at_kd_20(replays):
    _, results = replays
    logs = results[20.0].logs
    s = settling(logs.t, logs.q, logs.q_d, logs.v_d)
    assert len(s.times) >= 10  # every gripper close and open holds the arm still
    # The final hold (1 s, nothing else acting) is where the decay can be watched whole.
    assert s.settled[-1] and s.times[-1] < 0.5, f"final hold settled in {s.times[-1]:.2f} s"
    slow = settling(*(lambda lg: (lg.t, lg.q, lg.q_d, lg.v_d))(results[5.0].logs))
    assert slow.times[-1] > s.times[-1], "Kd = 5 should settle more slowly than Kd = 20"


def test_gains_cli_writes_plot_and_table(position_run, tmp_path):
    out, _ = position_run
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "cake_drake.gains",
            "--kd",
            "20",
            "5",
            "--reference",
            str(out / "trajectory.npz"),
            "--out",
            str(tmp_path),
            "--quiet",
        ],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    data = json.loads((tmp_path / "gains.json").read_text())
    assert [run["kd"] for run in data["runs"]] == [20.0, 5.0]
    assert len(data["runs"][0]["rms_tracking_error"]) == 7
    assert (tmp_path / "kd_comparison.png").stat().st_size > 10_000
    assert (tmp_path / "step_response.png").stat().st_size > 10_000
    assert "Kd" in r.stdout and "overshoot theory" in r.stdout and "with Ki 200" in r.stdout
    steps = {s["kd"]: s for s in data["theory"]["step"]}
    assert steps[5.0]["zeta"] == 0.25 and abs(steps[5.0]["overshoot_theory"] - 0.444) < 1e-3


def test_theory_of_the_error_equation():
    from cake_drake.gains.step import theory

    assert theory(100, 20).zeta == 1.0 and theory(100, 20).overshoot == 0.0
    assert abs(theory(100, 5).overshoot - 0.4443) < 1e-3  # exp(-zeta pi / sqrt(1 - zeta^2))
    assert abs(theory(100, 5).settling_s - 1.41) < 0.01
    assert abs(theory(100, 20).settling_s - 0.58) < 0.01
    assert theory(100, 40).overshoot == 0.0 and theory(100, 40).settling_s > 0.58


@pytest.mark.parametrize("kd", [20.0, 5.0])
def test_every_joints_step_response_is_the_theorys_within_ten_percent(kd):
    """With the control plant matching the arm, computed torque leaves each joint the
    mass-spring-damper e'' + Kd e' + Kp e = 0 (the exercise's Kd lesson)."""
    from cake_drake.gains.step import step_response, theory

    r, th = step_response(100.0, kd), theory(100.0, kd)
    assert np.all(np.abs(r.overshoot - th.overshoot) <= 0.1 * max(th.overshoot, 0.05))
    assert np.all(np.abs(r.settling_s - th.settling_s) <= 0.1 * th.settling_s)
    assert np.all(np.abs(r.steady) < 1e-4)


def test_an_unmodelled_payload_leaves_a_steady_error_integral_action_removes():
    from cake_drake.gains.step import payload_response

    sag = payload_response(0.5, 100.0, 20.0, ki=0.0).steady
    assert np.max(np.abs(sag)) > 0.01  # > 10 mrad, however long it waits
    stiffer = payload_response(0.5, 400.0, 40.0, ki=0.0).steady
    assert 0 < np.max(np.abs(stiffer)) < np.max(np.abs(sag))  # Kp shrinks it, never removes it
    assert np.max(np.abs(payload_response(0.5, 100.0, 20.0, ki=200.0).steady)) < 5e-4


def test_gains_cli_bad_reference_is_one_line(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.gains", "--reference", str(bad), "--out", str(tmp_path)],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2
    assert r.stderr.startswith("error: ") and r.stderr.count("\n") == 1
    assert not (tmp_path / "gains.json").exists()
