"""Joint trajectories: straight lines in joint space between IK solutions, timed smoothly.

Each move is a quintic (minimum-jerk) profile, velocity and acceleration zero at both
ends, so the jerk is bounded. Its duration is the shortest that keeps every joint within
``velocity_fraction`` of its velocity limit and ``acceleration_fraction`` of its
acceleration limit (both read from the plant, which has them from the robot's URDF) (the
quintic peaks at 1.875 d/T in velocity and 10/sqrt(3) d/T^2 in acceleration for a
distance d). Gripper closing and opening are holds of ``gripper_time`` seconds.

A waypoint that needs no stop (no gripper change, nothing to measure there) is blended
through: the next move starts before the last one ends and the two are summed
(superposition blending, as industrial controllers do), so the arm rounds the corner
instead of stopping at it. The overlap is ``blend`` of the shorter move at most, and
shrunk until the sum keeps within the same velocity and acceleration bounds; position,
velocity and acceleration stay continuous. At most two moves are ever summed.

``trajectory.npz`` (see :func:`cake_drake.formats.save_npz`) holds, per sample:
``t`` (s), ``q``, ``qd``, ``qdd`` (7 arm joints: rad, rad/s, rad/s^2), ``gripper``
(commanded opening of each finger, m), ``phase`` (index into ``phases``), ``action``
(index into ``actions``; -1 when idle), plus ``phases`` and ``actions`` as strings.
"""

import bisect
from dataclasses import dataclass, field

import numpy as np

from cake_drake.formats import PHASE_NAMES

GRIPPER_OPEN = 0.04  # m per finger (8 cm between the fingers)
GRIPPER_CLOSED = 0.0  # commanded shut: the cube stops the fingers, the PD squeezes

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

    Moves use ``velocity_fraction`` and ``acceleration_fraction`` of the robot's limits
    (Franka's datasheet values, in the URDF): by default all of it, which the reference
    never exceeds, blends included. The moves that start or end beside a cube or a tower
    (``gentle_phases``) use ``gentle`` times that: below 1 for a slower approach.
    """

    velocity_fraction: float = 1.0
    acceleration_fraction: float = 1.0
    gentle: float = 1.0
    gentle_phases: list[str] = field(default_factory=lambda: ["grasp", "place", "retract"])
    #: Fraction of the shorter of two consecutive moves by which the second may start
    #: before the first ends (0 = stop at every waypoint; at most 0.5).
    blend: float = 0.5
    min_move: float = 0.1  # s, shortest move
    gripper_time: float = 0.2  # s, a close or an open (the fingers' 0.2 m/s limit)
    settle_time: float = 0.05  # s, still before the fingers close or open

    def scale(self, phase: str) -> float:
        """The fraction of the limits' fractions that moves of ``phase`` use."""
        return self.gentle if phase in self.gentle_phases else 1.0

    def move_duration(
        self, q0: np.ndarray, q1: np.ndarray, limits: JointLimits, phase: str = "transport"
    ) -> float:
        scale = self.scale(phase)
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
    #: Whether the arm moves (False: a hold). Asked every step, so computed once.
    moves: bool = field(init=False, compare=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "moves", bool(np.any(self.q1 != self.q0)))

    def __deepcopy__(self, memo):  # immutable: share, do not copy
        return self

    @property
    def end(self) -> float:
        return self.t0 + self.duration

    def at(self, t):
        """Displacement from ``q0``, velocity and acceleration at ``t`` (scalar or array)."""
        dq = self.q1 - self.q0
        if isinstance(t, float):
            s, ds, dds = _quintic(min(max((t - self.t0) / self.duration, 0.0), 1.0))
            return s * dq, (ds / self.duration) * dq, (dds / self.duration**2) * dq
        tau = np.clip((np.asarray(t, float) - self.t0) / self.duration, 0.0, 1.0)
        s, ds, dds = _quintic(tau)
        return (
            np.multiply.outer(s, dq),
            np.multiply.outer(ds / self.duration, dq),
            np.multiply.outer(dds / self.duration**2, dq),
        )


def _quintic(tau):
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
    #: No move appended from now on may start before this time (see :meth:`resume_at`).
    earliest: float = -np.inf

    def copy(self) -> "JointTrajectory":
        """A new trajectory sharing the (immutable) segments, to append to."""
        return JointTrajectory(
            self.start_q,
            self.limits,
            self.start_time,
            list(self.segments),
            list(self._starts),
            self.earliest,
        )

    def resume_at(self, t: float, phase: str, action: int) -> None:
        """Appending at time ``t`` (the present): past the end, hold still until ``t``;
        before it, the next move may blend into the last one, but not start before ``t``."""
        if t > self.end_time:
            self.hold(t - self.end_time, phase, action)
        self.earliest = t

    def ready_time(self, blend: float) -> float:
        """When the next move may start: the end, or before it when the last segment is a
        move the next one can blend into (``blend`` of its duration before)."""
        last = self.segments[-1] if self.segments else None
        if last is None or not last.moves:
            return self.end_time
        return self.end_time - blend * last.duration

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

    def _append(self, duration, q1, phase, action, gripper, t0=None) -> None:
        seg = Segment(
            self.end_time if t0 is None else t0,
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
        """Quintic move from the current end to ``q1``; the gripper keeps its command.
        When the last segment is a move too, this one blends into it (see the module)."""
        q1 = np.asarray(q1, float)
        duration = timing.move_duration(self.end_q, q1, self.limits, phase)
        end = self.end_time
        overlap = self._overlap(q1, duration, phase, timing)
        self._append(duration, q1, phase, action, self.end_gripper, end - overlap)

    def _overlap(self, q1, duration: float, phase: str, timing: Timing) -> float:
        """The longest overlap with the last move (up to ``timing.blend`` of the shorter
        one, not before :attr:`earliest`) whose sum keeps within both moves' bounds."""
        last = self.segments[-1] if self.segments else None
        if last is None or not last.moves or timing.blend <= 0:
            return 0.0
        longest = min(timing.blend * min(last.duration, duration), last.end - self.earliest)
        if longest <= 0:
            return 0.0
        prev_phase = PHASE_NAMES[last.phase]
        scale = min(timing.scale(phase), timing.scale(prev_phase))
        v_max = scale * timing.velocity_fraction * self.limits.velocity
        a_max = scale * timing.acceleration_fraction * self.limits.acceleration
        for k in range(8, 0, -1):  # the longest of 8/8 .. 1/8 of it that keeps the bounds
            overlap = longest * k / 8
            nxt = Segment(last.end - overlap, duration, last.q1, q1, 0, 0, 0.0, 0.0)
            ts = np.linspace(nxt.t0, last.end, 33)
            _, v0, a0 = last.at(ts)
            _, v1, a1 = nxt.at(ts)
            if np.all(np.abs(v0 + v1) <= v_max * (1 + 1e-9)) and np.all(
                np.abs(a0 + a1) <= a_max * (1 + 1e-9)
            ):
                return overlap
        return 0.0

    def hold(self, duration: float, phase: str, action: int, gripper: float | None = None) -> None:
        """Stay still for ``duration``; the finger command ramps to ``gripper`` meanwhile.

        A ramp rather than a step: the fingers meet the cube gently, and on opening both
        let go together instead of one pushing the cube as the other leaves.
        """
        g = self.end_gripper if gripper is None else gripper
        self._append(duration, self.end_q, phase, action, g)

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float, int, int]:
        """Everything at time ``t``: q, q-dot, q-double-dot (held at the ends), then the
        finger command, its rate, the phase index and the action index (idle: 0, -1)."""
        if not self.segments or t < self.start_time:
            q = np.asarray(self.start_q, float)
            zero = np.zeros_like(q)
            return q, zero, zero, self.end_gripper, 0.0, 0, -1
        i = max(bisect.bisect_right(self._starts, t) - 1, 0)
        seg = self.segments[i]
        q, v, a = seg.at(t)
        prev = self.segments[i - 1] if i > 0 else None
        if prev is not None and t < prev.end:  # blending: the last move is still running
            q0, v0, a0 = prev.at(t)
            q, v, a = prev.q0 + q0 + q, v0 + v, a0 + a
        else:
            q = seg.q0 + q
        if t > self.end_time:
            return q, v, a, self.end_gripper, 0.0, 0, -1
        if seg.gripper == seg.gripper0:
            return q, v, a, seg.gripper, 0.0, seg.phase, seg.action
        rate = (seg.gripper - seg.gripper0) / seg.duration
        return q, v, a, seg.gripper0 + rate * (t - seg.t0), rate, seg.phase, seg.action

    def at_many(self, ts) -> tuple[np.ndarray, ...]:
        """:meth:`at` at every time of ``ts`` at once, as arrays (q, q-dot, q-double-dot
        of shape (N, joints); finger command, its rate, phase and action index of shape
        (N,)). Each row is :meth:`at`'s, bit for bit: the same operations in the same
        order, element by element."""
        ts = np.asarray(ts, float)
        n, start_q = len(ts), np.asarray(self.start_q, float)
        shape = (n, len(start_q))
        q, v, a = np.empty(shape), np.zeros(shape), np.zeros(shape)
        grip, rate = np.full(n, float(self.end_gripper)), np.zeros(n)
        phase, action = np.zeros(n, dtype=np.int64), np.full(n, -1, dtype=np.int64)
        q[:] = start_q
        if not self.segments:
            return q, v, a, grip, rate, phase, action
        live = ts >= self.start_time
        index = np.maximum(np.searchsorted(self._starts, ts, side="right") - 1, 0)
        end = self.end_time
        for i in np.unique(index[live]):
            rows = np.flatnonzero(live & (index == i))
            t, seg = ts[rows], self.segments[i]
            dq, dv, da = seg.at(t)
            prev = self.segments[i - 1] if i > 0 else None
            blend = t < prev.end if prev is not None else np.zeros(len(t), bool)
            q0, v0, a0 = prev.at(t[blend]) if blend.any() else (None, None, None)
            if blend.any():
                q[rows[blend]] = prev.q0 + q0 + dq[blend]
                v[rows[blend]] = v0 + dv[blend]
                a[rows[blend]] = a0 + da[blend]
            q[rows[~blend]] = seg.q0 + dq[~blend]
            v[rows[~blend]], a[rows[~blend]] = dv[~blend], da[~blend]
            running = rows[t <= end]
            phase[running], action[running] = seg.phase, seg.action
            if seg.gripper == seg.gripper0:
                grip[running] = seg.gripper
            else:
                r = (seg.gripper - seg.gripper0) / seg.duration
                grip[running] = seg.gripper0 + r * (ts[running] - seg.t0)
                rate[running] = r
        return q, v, a, grip, rate, phase, action

    def evaluate(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, q-dot, q-double-dot at time ``t`` (held at the ends)."""
        return self.at(t)[:3]

    def labels(self, t: float) -> tuple[float, float, int, int]:
        """(finger command, its rate, phase index, action index) at time ``t``."""
        return self.at(t)[3:]

    def sample(self, dt: float, t_end: float | None = None) -> dict[str, np.ndarray]:
        """Every field of ``trajectory.npz`` sampled every ``dt`` seconds."""
        t_end = self.end_time if t_end is None else t_end
        ts = np.arange(self.start_time, t_end + dt / 2, dt)
        q, v, a, grip, _, phase, action = self.at_many(ts)
        return {
            "t": ts,
            "q": q,
            "qd": v,
            "qdd": a,
            "gripper": grip,
            "phase": phase.astype(np.int16),
            "action": action.astype(np.int16),
        }
