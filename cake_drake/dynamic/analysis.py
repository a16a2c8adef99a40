"""Reading the controller's logs: where the arm is still, how fast it settles."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: The reference counts as still when every joint's desired speed is below this (rad/s);
#: a spline fitted through recorded samples is never exactly still.
STILL_SPEED = 1e-3


def arrivals(t: np.ndarray, v_d: np.ndarray) -> list[tuple[int, int]]:
    """(arrival, departure) sample indices of every stretch where the reference is still.

    An arrival is where the reference comes to rest after moving (a waypoint reached);
    the stretch lasts until it moves again (or the log ends).
    """
    still = np.max(np.abs(v_d), axis=1) < STILL_SPEED
    spans = []
    i = 1
    while i < len(t):
        if still[i] and not still[i - 1]:
            j = i
            while j < len(t) and still[j]:
                j += 1
            spans.append((i, j))
            i = j
        else:
            i += 1
    return spans


@dataclass(frozen=True)
class Settling:
    """Settling after each waypoint where the reference holds still.

    ``times[i]``: seconds from the arrival until the error stays within ``threshold`` of
    the value it ends the hold with (a steady offset, e.g. from the unmodelled cube in
    the hand, is not counted as motion); ``settled[i]`` is False when it was still
    moving at the end of the hold, and ``times[i]`` is then the hold's length.
    """

    threshold: float  # rad, on the largest joint's deviation from its final error
    times: tuple[float, ...]
    settled: tuple[bool, ...]

    @property
    def median(self) -> float:
        return float(np.median(self.times)) if self.times else 0.0

    @property
    def worst(self) -> float:
        return float(np.max(self.times)) if self.times else 0.0


def settling(
    t: np.ndarray,
    q: np.ndarray,
    q_d: np.ndarray,
    v_d: np.ndarray,
    threshold: float = 2e-4,
    min_hold: float = 0.1,
) -> Settling:
    """How long after each waypoint the tracking error takes to settle (see :class:`Settling`).

    Only holds of at least ``min_hold`` seconds are judged: a waypoint the reference
    passes straight through leaves no time to watch the error decay.
    """
    err = q - q_d
    times, ok = [], []
    for a, d in arrivals(t, v_d):
        if t[d - 1] - t[a] < min_hold:
            continue
        dev = np.max(np.abs(err[a:d] - err[d - 1]), axis=1)
        outside = np.nonzero(dev >= threshold)[0]
        hold = float(t[d - 1] - t[a])
        if len(outside) == 0:
            times.append(0.0), ok.append(True)
        else:
            settle = float(t[a + outside[-1] + 1] - t[a])
            # Still drifting in the last 20 % of the hold: not settled.
            settled = settle < 0.8 * hold
            times.append(settle if settled else hold), ok.append(settled)
    return Settling(threshold, tuple(times), tuple(ok))


def stationary_samples(v: np.ndarray, v_d: np.ndarray, speed: float = 1e-3) -> np.ndarray:
    """Mask of samples where both the arm and its reference are (nearly) still."""
    return (np.max(np.abs(v), axis=1) < speed) & (np.max(np.abs(v_d), axis=1) < STILL_SPEED)
