"""Joint trajectories: straight lines in joint space between IK solutions, timed smoothly.

Each move is a quintic (minimum-jerk) blend from rest to rest, so velocity and
acceleration are zero at every waypoint and the jerk is bounded. Its duration is the
shortest that keeps every joint within ``velocity_fraction`` of its velocity limit and
``acceleration_fraction`` of its acceleration limit (both read from the plant, which has
them from the robot's URDF) (the quintic peaks at
1.875 d/T in velocity and 10/sqrt(3) d/T^2 in acceleration for a distance d).
Gripper closing and opening are holds of ``gripper_time`` seconds.

``trajectory.npz`` (see :func:`save_npz`) holds, per sample:
``t`` (s), ``q``, ``qd``, ``qdd`` (7 arm joints: rad, rad/s, rad/s^2), ``gripper``
(commanded opening of each finger, m), ``phase`` (index into ``phases``), ``action``
(index into ``actions``; -1 when idle), plus ``phases`` and ``actions`` as strings.
"""

import bisect
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cake_drake.errors import InputError

GRIPPER_OPEN = 0.04  # m per finger (8 cm between the fingers)
GRIPPER_CLOSED = 0.0  # commanded shut: the cube stops the fingers, the PD squeezes
PHASE_NAMES = ("idle", "pre-grasp", "grasp", "lift", "transport", "place", "retract")

_V_PEAK = 1.875  # quintic: peak of ds/dtau
_A_PEAK = 10.0 / np.sqrt(3.0)  # quintic: peak of |d2s/dtau2|


@dataclass(frozen=True)
class JointLimits:
    """The arm's velocity and acceleration limits (per joint), read from the plant."""

    velocity: np.ndarray  # rad/s
    acceleration: np.ndarray  # rad/s^2

    @classmethod
    def from_plant(cls, plant) -> "JointLimits":
        """The limits the robot's model declares (the URDF's ``velocity`` and
        ``drake:acceleration``), for the plant's joints in order."""
        return cls(
            np.asarray(plant.GetVelocityUpperLimits(), float).copy(),
            np.asarray(plant.GetAccelerationUpperLimits(), float).copy(),
        )


@dataclass
class Timing:
    """How fast the arm may move (the ``motion.timing`` section of a scenario).

    Free-space moves (pre-grasp, lift, transport) use ``velocity_fraction`` and
    ``acceleration_fraction`` of the robot's limits; the moves that start or end
    beside a cube or a tower (grasp, place, retract) are ``gentle`` times that, so an
    overshoot there stays small.
    """

    velocity_fraction: float = 0.8
    acceleration_fraction: float = 0.7
    gentle: float = 0.7
    gentle_phases: list[str] = field(default_factory=lambda: ["grasp", "place", "retract"])
    min_move: float = 0.2  # s, shortest move
    gripper_time: float = 0.2  # s, a close or an open (the fingers' 0.2 m/s limit)
    settle_time: float = 0.05  # s, still before the fingers close or open

    def move_duration(
        self, q0: np.ndarray, q1: np.ndarray, limits: JointLimits, phase: str = "transport"
    ) -> float:
        scale = self.gentle if phase in self.gentle_phases else 1.0
        d = np.abs(np.asarray(q1) - np.asarray(q0))
        t_v = _V_PEAK * d / (scale * self.velocity_fraction * limits.velocity)
        t_a = np.sqrt(_A_PEAK * d / (scale * self.acceleration_fraction * limits.acceleration))
        return float(max(self.min_move, t_v.max(), t_a.max()))


@dataclass(frozen=True)
class Segment:
    t0: float
    duration: float
    q0: np.ndarray
    q1: np.ndarray
    phase: int  # index into PHASE_NAMES
    action: int
    gripper: float  # finger command at the end of the segment (m per finger)
    gripper0: float  # ... at its start: a hold that changes it ramps linearly

    def __deepcopy__(self, memo):  # immutable: share, do not copy
        return self


def _quintic(tau: float) -> tuple[float, float, float]:
    t2 = tau * tau
    s = t2 * tau * (10 - 15 * tau + 6 * t2)
    ds = 30 * t2 * (1 - 2 * tau + t2)
    dds = 60 * tau * (1 - 3 * tau + 2 * t2)
    return s, ds, dds


@dataclass
class JointTrajectory:
    """A sequence of timed segments, appended as the plan unfolds.

    Moves are timed against ``limits`` (the arm's, from the plant).
    """

    start_q: np.ndarray
    limits: JointLimits
    start_time: float = 0.0
    segments: list[Segment] = field(default_factory=list)
    _starts: list[float] = field(default_factory=list)

    def copy(self) -> "JointTrajectory":
        """A new trajectory sharing the (immutable) segments, to append to."""
        return JointTrajectory(
            self.start_q, self.limits, self.start_time, list(self.segments), list(self._starts)
        )

    def assign(self, other: "JointTrajectory") -> None:
        """Take ``other``'s segments (a copy of this one, extended)."""
        self.segments[:] = other.segments
        self._starts[:] = other._starts

    @property
    def end_time(self) -> float:
        s = self.segments[-1] if self.segments else None
        return s.t0 + s.duration if s else self.start_time

    @property
    def end_q(self) -> np.ndarray:
        return self.segments[-1].q1 if self.segments else np.asarray(self.start_q, float)

    @property
    def end_gripper(self) -> float:
        return self.segments[-1].gripper if self.segments else GRIPPER_OPEN

    def _append(self, duration, q1, phase, action, gripper) -> None:
        seg = Segment(
            self.end_time,
            duration,
            self.end_q,
            np.asarray(q1, float),
            PHASE_NAMES.index(phase),
            action,
            gripper,
            self.end_gripper,
        )
        self.segments.append(seg)
        self._starts.append(seg.t0)

    def move(self, q1, phase: str, action: int, timing: Timing) -> None:
        """Quintic move from the current end to ``q1``; the gripper keeps its command."""
        self._append(
            timing.move_duration(self.end_q, q1, self.limits, phase),
            q1,
            phase,
            action,
            self.end_gripper,
        )

    def hold(self, duration: float, phase: str, action: int, gripper: float | None = None) -> None:
        """Stay still for ``duration``; the finger command ramps to ``gripper`` meanwhile.

        A ramp rather than a step: the fingers meet the cube gently, and on opening both
        let go together instead of one pushing the cube as the other leaves.
        """
        g = self.end_gripper if gripper is None else gripper
        self._append(duration, self.end_q, phase, action, g)

    def _segment(self, t: float) -> Segment | None:
        if not self.segments or t < self.start_time:
            return None
        i = bisect.bisect_right(self._starts, t) - 1
        return self.segments[max(i, 0)]

    def evaluate(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, q-dot, q-double-dot at time ``t`` (held at the ends)."""
        seg = self._segment(t)
        if seg is None:
            q = np.asarray(self.start_q, float)
            return q, np.zeros_like(q), np.zeros_like(q)
        tau = min(max((t - seg.t0) / seg.duration, 0.0), 1.0)
        s, ds, dds = _quintic(tau)
        dq = seg.q1 - seg.q0
        return seg.q0 + s * dq, dq * (ds / seg.duration), dq * (dds / seg.duration**2)

    def labels(self, t: float) -> tuple[float, float, int, int]:
        """(finger command, its rate, phase index, action index) at time ``t``."""
        seg = self._segment(t)
        if seg is None or t > self.end_time:
            return self.end_gripper, 0.0, 0, -1
        if seg.gripper == seg.gripper0:
            return seg.gripper, 0.0, seg.phase, seg.action
        rate = (seg.gripper - seg.gripper0) / seg.duration
        return seg.gripper0 + rate * (t - seg.t0), rate, seg.phase, seg.action

    def sample(self, dt: float, t_end: float | None = None) -> dict[str, np.ndarray]:
        """Every field of ``trajectory.npz`` sampled every ``dt`` seconds."""
        t_end = self.end_time if t_end is None else t_end
        ts = np.arange(self.start_time, t_end + dt / 2, dt)
        qs, vs, accs, grip, phase, action = [], [], [], [], [], []
        for t in ts:
            q, v, a = self.evaluate(t)
            g, _, p, k = self.labels(t)
            qs.append(q), vs.append(v), accs.append(a)
            grip.append(g), phase.append(p), action.append(k)
        return {
            "t": ts,
            "q": np.array(qs),
            "qd": np.array(vs),
            "qdd": np.array(accs),
            "gripper": np.array(grip),
            "phase": np.array(phase, dtype=np.int16),
            "action": np.array(action, dtype=np.int16),
        }


def save_npz(path: str | Path, samples: dict[str, np.ndarray], actions: list[str]) -> None:
    """Write samples plus the phase and action names (whole, or not at all)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".part.npz")
    np.savez_compressed(
        tmp, **samples, phases=np.array(PHASE_NAMES), actions=np.array(actions, dtype=str)
    )
    tmp.replace(path)


REQUIRED = ("t", "q", "gripper")


def load_npz(path: str | Path) -> dict[str, np.ndarray]:
    """Read a ``trajectory.npz``; bad files give one clear line."""
    path = Path(path)
    expected = "expected a trajectory.npz written by python -m cake_drake.run"
    try:
        with np.load(path, allow_pickle=False) as data:
            if not hasattr(data, "files"):  # a bare .npy array, not an archive
                raise InputError(f"{path}: a single .npy array, not an .npz archive; {expected}")
            out = {k: data[k] for k in data.files}
    except FileNotFoundError:
        raise InputError(f"{path}: no such file ({expected})") from None
    except InputError:
        raise
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, TypeError) as e:
        raise InputError(f"{path}: not a readable .npz trajectory ({e}); {expected}") from None
    numeric = [k for k in ("t", "q", "gripper") if k in out and out[k].dtype.kind not in "iuf"]
    if numeric:
        raise InputError(
            f"{path}: array {numeric[0]!r} must hold numbers, not {out[numeric[0]].dtype}"
        )
    missing = [k for k in REQUIRED if k not in out]
    if missing:
        raise InputError(
            f"{path}: missing array {missing[0]!r}; a trajectory needs {', '.join(REQUIRED)}"
        )
    t, q = out["t"], out["q"]
    if q.ndim != 2 or q.shape[1] != 7 or len(t) != len(q) or len(t) < 4:
        raise InputError(
            f"{path}: q has shape {q.shape} for {len(t)} times; expected (N, 7) with N >= 4"
        )
    if not np.all(np.diff(t) > 0):
        raise InputError(f"{path}: times in 't' must strictly increase")
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(t))):
        raise InputError(f"{path}: 't' and 'q' must be finite numbers")
    return out
