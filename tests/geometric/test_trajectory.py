"""Joint trajectories: limits, smoothness, gripper ramps, trajectory.npz round trip and errors."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from cake_drake.errors import InputError
from cake_drake.formats import PHASE_NAMES, load_npz, save_npz
from cake_drake.geometric.ik import Kinematics
from cake_drake.geometric.trajectory import (
    GRIPPER_CLOSED,
    GRIPPER_OPEN,
    JointTrajectory,
    Timing,
)
from cake_drake.world.scene import Q_HOME

DT = 1e-3
TIMING = Timing()
#: Franka's datasheet, independently of the URDF the plant reads its limits from.
PANDA_VELOCITY = np.array([2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61])  # rad/s
PANDA_ACCELERATION = np.array([15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0])  # rad/s^2


def test_the_plant_has_the_datasheet_velocity_and_acceleration_limits():
    limits = Kinematics().limits
    np.testing.assert_array_equal(limits.velocity, PANDA_VELOCITY)
    np.testing.assert_array_equal(limits.acceleration, PANDA_ACCELERATION)


@pytest.fixture(scope="module")
def limits():
    kin = Kinematics()
    return kin.lower, kin.upper


@pytest.fixture(scope="module")
def trajectory(limits):
    """Moves between configurations spread over the joint range, holds and gripper ramps."""
    lower, upper = limits
    rng = np.random.default_rng(2)
    traj = JointTrajectory(Q_HOME.copy(), Kinematics().limits)
    phases = ["pre-grasp", "grasp", "lift", "transport", "place", "retract"]
    for i in range(12):
        # Near the limits too: a straight line between in-limit points stays in limits.
        q = rng.uniform(lower + 0.01, upper - 0.01) if i % 3 else Q_HOME + 0.02 * i
        phase = phases[i % len(phases)]
        traj.move(q, phase, i // 3, TIMING)
        if phase == "grasp":
            traj.hold(TIMING.settle_time, phase, i // 3)
            traj.hold(TIMING.gripper_time, phase, i // 3, gripper=GRIPPER_CLOSED)
        if phase == "place":
            traj.hold(TIMING.gripper_time, phase, i // 3, gripper=GRIPPER_OPEN)
    return traj


@pytest.fixture(scope="module")
def samples(trajectory):
    return trajectory.sample(DT)


def test_positions_stay_within_joint_limits(samples, limits):
    lower, upper = limits
    assert np.all(samples["q"] >= lower - 1e-12) and np.all(samples["q"] <= upper + 1e-12)


def test_velocity_and_acceleration_within_the_stated_fractions_of_the_limits(samples):
    v_max = TIMING.velocity_fraction * PANDA_VELOCITY
    a_max = TIMING.acceleration_fraction * PANDA_ACCELERATION
    assert np.all(np.abs(samples["qd"]) <= v_max * (1 + 1e-9))
    assert np.all(np.abs(samples["qdd"]) <= a_max * (1 + 1e-9))


def test_each_move_is_as_fast_as_the_limits_allow(trajectory):
    """Durations come from the limits, not a fixed time: one joint reaches its bound."""
    for seg in trajectory.segments:
        d = np.abs(seg.q1 - seg.q0)
        if not d.any() or seg.duration <= TIMING.min_move:
            continue
        scale = TIMING.gentle if PHASE_NAMES[seg.phase] in TIMING.gentle_phases else 1.0
        v_ratio = 1.875 * d / seg.duration / (scale * TIMING.velocity_fraction * PANDA_VELOCITY)
        a_ratio = (10 / np.sqrt(3)) * d / seg.duration**2
        a_ratio /= scale * TIMING.acceleration_fraction * PANDA_ACCELERATION
        assert max(v_ratio.max(), a_ratio.max()) == pytest.approx(1.0, rel=1e-9)


def test_rest_where_the_arm_must_stop_and_derivatives_consistent(trajectory, samples):
    """Still before and after every hold (the fingers close or open there) and at the
    ends; q, q-dot and q-double-dot continuous everywhere, blends included."""
    segs = trajectory.segments
    stops = {segs[0].t0, segs[-1].end}
    for seg in segs:
        if not seg.moves:
            stops |= {seg.t0, seg.end}
    for t in stops:
        _, v, a = trajectory.evaluate(t)
        assert np.allclose(v, 0, atol=1e-12) and np.allclose(a, 0, atol=1e-12)
    # qd and qdd are the derivatives of q and qd (central differences).
    q, qd, qdd = samples["q"], samples["qd"], samples["qdd"]
    np.testing.assert_allclose((q[2:] - q[:-2]) / (2 * DT), qd[1:-1], atol=5e-3)
    np.testing.assert_allclose((qd[2:] - qd[:-2]) / (2 * DT), qdd[1:-1], atol=0.1)


def test_consecutive_moves_blend_and_holds_do_not(trajectory):
    pairs = list(itertools.pairwise(trajectory.segments))
    blended = [(a, b) for a, b in pairs if b.t0 < a.end - 1e-12]
    assert blended, "no two consecutive moves overlap"
    for a, b in blended:
        assert a.moves and b.moves
        assert a.end - b.t0 <= TIMING.blend * min(a.duration, b.duration) + 1e-12
    for a, b in pairs:
        if not a.moves or not b.moves:
            assert b.t0 == pytest.approx(a.end, abs=1e-12)


def test_blending_saves_time_and_zero_blend_stops_everywhere(limits):
    lower, upper = limits
    rng = np.random.default_rng(5)
    qs = [rng.uniform(lower + 0.01, upper - 0.01) for _ in range(6)]
    ends = {}
    for blend in (0.0, 0.5):
        timing = Timing(blend=blend)
        traj = JointTrajectory(Q_HOME.copy(), Kinematics().limits)
        for q in qs:
            traj.move(q, "transport", 0, timing)
        ends[blend] = traj.end_time
        if blend == 0.0:
            assert ends[0.0] == pytest.approx(sum(s.duration for s in traj.segments))
    assert ends[0.5] < ends[0.0] * 0.95


def test_a_move_appended_later_never_starts_in_the_past():
    """Appended while the last move is running (the next step, planned once the last
    move may be blended into), the next move starts at the present at the earliest;
    appended after the end, the arm holds still until the present."""
    traj = JointTrajectory(Q_HOME.copy(), Kinematics().limits)
    traj.move(Q_HOME + 0.5, "transport", 0, TIMING)
    ready = traj.ready_time(TIMING.blend)
    assert traj.segments[-1].t0 < ready < traj.end_time
    now = traj.end_time - 0.01  # a little after it became ready
    later = traj.copy()
    later.resume_at(now, "idle", -1)
    later.move(Q_HOME, "pre-grasp", 1, TIMING)
    assert now <= later.segments[-1].t0 < traj.end_time
    after = traj.copy()
    after.resume_at(traj.end_time + 0.3, "idle", -1)
    after.move(Q_HOME, "pre-grasp", 1, TIMING)
    assert not after.segments[-2].moves
    assert after.segments[-1].t0 == pytest.approx(traj.end_time + 0.3)


def test_jerk_is_bounded_by_the_quintic_peak(trajectory, samples):
    """Finite-difference jerk never exceeds twice the largest segment's 60 d / T^3 (two
    moves at most are summed where they blend)."""
    segs = trajectory.segments
    bound = 2 * max(60 * np.max(np.abs(s.q1 - s.q0)) / s.duration**3 for s in segs)
    jerk = np.diff(samples["qdd"], axis=0) / DT
    assert np.all(np.isfinite(jerk))
    assert np.max(np.abs(jerk)) <= bound * 1.001
    # And per joint: no step in acceleration anywhere (the acceleration is continuous).
    assert np.max(np.abs(np.diff(samples["qdd"], axis=0))) <= bound * DT * 1.001


def test_gripper_ramps_during_holds_and_labels_follow(trajectory, samples):
    g = samples["gripper"]
    assert g[0] == GRIPPER_OPEN and set(np.unique(g)) >= {GRIPPER_OPEN, GRIPPER_CLOSED}
    ramp_rate = (GRIPPER_OPEN - GRIPPER_CLOSED) / TIMING.gripper_time
    assert np.max(np.abs(np.diff(g))) <= ramp_rate * DT * 1.01
    closing = [s for s in trajectory.segments if s.gripper != s.gripper0]
    assert closing
    seg = closing[0]
    mid = seg.t0 + seg.duration / 2
    finger, rate, phase, action = trajectory.labels(mid)
    assert finger == pytest.approx((seg.gripper + seg.gripper0) / 2)
    assert rate == pytest.approx((seg.gripper - seg.gripper0) / seg.duration)
    assert PHASE_NAMES[phase] in ("grasp", "place") and action == seg.action
    assert trajectory.labels(trajectory.end_time + 1.0)[2:] == (0, -1)  # idle afterwards


def test_at_many_is_at_bit_for_bit(trajectory):
    """The vectorised evaluation (WaypointIk's tape, trajectory.npz) repeats :meth:`at` row
    by row exactly: the same bits, before the start, in blends, holds and ramps, past the
    end, at the simulation's own step times (k * period)."""
    traj = trajectory.copy()
    traj.start_time = 0.05
    ks = np.arange(0, round(traj.end_time / 0.01) + 40)
    times = np.concatenate([ks * 0.01, [s.t0 for s in traj.segments], [traj.end_time]])
    many = traj.at_many(times)
    pairs = zip(traj.segments, traj.segments[1:], strict=False)
    assert any(nxt.t0 < seg.end for seg, nxt in pairs)  # blends are among them
    for i, t in enumerate(times):
        for one, rows in zip(traj.at(float(t)), many, strict=True):
            assert np.asarray(one, float).tobytes() == np.asarray(rows[i], float).tobytes(), t


def test_npz_round_trip(samples, tmp_path):
    path = tmp_path / "trajectory.npz"
    actions = ["(unstack a b)", "(put-down a)", "(pick-up c)", "(stack c d)"]
    save_npz(path, samples, actions)
    loaded = load_npz(path)
    for key, value in samples.items():
        np.testing.assert_array_equal(loaded[key], value)
    assert list(loaded["phases"]) == list(PHASE_NAMES)
    assert list(loaded["actions"]) == actions
    assert not list(tmp_path.glob("*.part*"))  # written whole, no leftovers


def _good(n=5):
    return {"t": np.arange(n) * 0.1, "q": np.zeros((n, 7)), "gripper": np.full(n, 0.04)}


def _write(path, **arrays):
    np.savez(path, **arrays)
    return path


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda p: p, "no such file"),
        (lambda p: (p.write_text("not an archive\n"), p)[1], "not a readable .npz"),
        (lambda p: _write(p, t=np.arange(5.0), gripper=np.zeros(5)), "missing array 'q'"),
        (lambda p: _write(p, **{**_good(), "q": np.zeros((5, 6))}), r"expected \(N, 7\)"),
        (lambda p: _write(p, **{**_good(), "q": np.zeros((4, 7))}), "disagree on the number"),
        (lambda p: _write(p, **{**_good(), "t": np.array([0, 1, 1, 2, 3.0])}), "increase"),
        (lambda p: _write(p, **{**_good(), "q": np.full((5, 7), np.nan)}), "finite"),
    ],
    ids=["missing", "text", "no-q", "six-joints", "length", "time-repeats", "nan"],
)
def test_bad_npz_files_are_input_errors(tmp_path, make, message):
    path = make(tmp_path / "trajectory.npz")
    with pytest.raises(InputError, match=message):
        load_npz(path)


@pytest.mark.parametrize(
    "content",
    [b"", b"PK\x03\x04truncated", "npy", "strings"],
    ids=["empty", "truncated-zip", "npy-not-npz", "string-times"],
)
def test_broken_npz_files_are_input_errors_too(tmp_path, content):
    path = tmp_path / "trajectory.npz"
    if content == "npy":
        with open(path, "wb") as f:
            np.save(f, np.zeros((5, 7)))
    elif content == "strings":
        _write(path, **{**_good(), "t": np.array(list("abcde"))})
    else:
        path.write_bytes(content)
    with pytest.raises(InputError):
        load_npz(path)


def _zip(path, members: dict[str, bytes]):
    import zipfile

    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in members.items():
            z.writestr(name, data)
    return path


def _npy(array) -> bytes:
    import io

    f = io.BytesIO()
    np.save(f, array)
    return f.getvalue()


def _npy_header(shape, descr="<f8") -> bytes:
    import io

    f = io.BytesIO()
    header = {"descr": descr, "fortran_order": False, "shape": shape}
    np.lib.format._write_array_header(f, header, (1, 0))
    return f.getvalue()


@pytest.mark.parametrize(
    "arrays, message",
    [
        ({"t": np.zeros((5, 2))}, r"array 't' has shape \(5, 2\)"),
        ({"actions": np.array("(pick-up a)")}, r"array 'actions' has shape \(\)"),
        ({"phases": np.array("idle")}, r"array 'phases' has shape \(\)"),
        ({"actions": np.arange(3.0)}, "array 'actions' must hold text"),
        ({"phase": np.zeros((5, 1))}, r"array 'phase' has shape \(5, 1\)"),
        ({"qd": np.zeros((5, 6))}, r"array 'qd' has shape \(5, 6\)"),
        ({"gripper": np.zeros(5, dtype=[("a", "<f8")])}, "must hold numbers"),
    ],
    ids=["t-2d", "actions-0d", "phases-0d", "actions-numbers", "phase-2d", "qd-6", "structured"],
)
def test_every_array_of_a_trajectory_is_checked_for_shape_and_kind(tmp_path, arrays, message):
    # Each of these passed the reader once and ended in a traceback from Drake or NumPy.
    path = _write(tmp_path / "trajectory.npz", **{**_good(), **arrays})
    with pytest.raises(InputError, match=message):
        load_npz(path)


def test_a_member_that_is_not_an_array_is_refused_before_it_is_decompressed(tmp_path):
    # 300 MiB of zeros under a name without .npy: a few hundred kB on disk; counted as
    # nothing by a reader that looks at .npy members only, then read in full.
    members = {f"{k}.npy": _npy(v) for k, v in _good().items()}
    members["padding"] = bytes(300 * 2**20)
    path = _zip(tmp_path / "trajectory.npz", members)
    assert path.stat().st_size < 2 * 2**20
    with pytest.raises(InputError, match="member 'padding' is not an array"):
        load_npz(path)


def test_a_negative_dimension_cannot_cancel_out_the_real_arrays(tmp_path):
    from cake_drake.formats import npz_headers

    members = {f"{k}.npy": _npy(v) for k, v in _good().items()}
    members["minus.npy"] = _npy_header((-(2**25), 8))  # -2 GiB first: the sum stays 0 ...
    members["big.npy"] = _npy_header((2**25, 8))  # ... after 2 GiB, claimed with nothing behind
    path = _zip(tmp_path / "trajectory.npz", members)
    with pytest.raises(InputError, match="negative dimension|more than 256 MiB"):
        npz_headers(path, "a trajectory")
    with pytest.raises(InputError, match="negative dimension|more than 256 MiB"):
        load_npz(path)


def test_a_run_given_a_damaged_reference_stops_in_one_line_before_simulating(tmp_path):
    import subprocess
    import sys

    members = {f"{k}.npy": _npy(v) for k, v in _good(8).items()}
    members["notes"] = bytes(64 * 2**20)
    ref = _zip(tmp_path / "ref.npz", members)
    out = tmp_path / "out"
    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.run", "--reference", str(ref), "--out", str(out)],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and "member 'notes' is not an array" in r.stderr
    assert not out.exists()
