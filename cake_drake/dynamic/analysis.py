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
    """Settling after each waypoint: seconds until the error stays below ``threshold``."""

    threshold: float  # rad, on the largest joint error
    times: tuple[float, ...]  # one per arrival; the hold's length if it never settled
    settled: tuple[bool, ...]

    @property
    def median(self) -> float:
        return float(np.median(self.times)) if self.times else 0.0

    @property
    def worst(self) -> float:
        return float(np.max(self.times)) if self.times else 0.0


def settling(
    t: np.ndarray, q: np.ndarray, q_d: np.ndarray, v_d: np.ndarray, threshold: float = 2e-4
) -> Settling:
    """How long after each waypoint the tracking error takes to stay below ``threshold``."""
    err = np.max(np.abs(q - q_d), axis=1)
    times, ok = [], []
    for a, d in arrivals(t, v_d):
        above = np.nonzero(err[a:d] >= threshold)[0]
        if len(above) == 0:
            times.append(0.0), ok.append(True)
        elif above[-1] == d - a - 1:  # still above at the end of the hold
            times.append(float(t[d - 1] - t[a])), ok.append(False)
        else:
            times.append(float(t[a + above[-1] + 1] - t[a])), ok.append(True)
    return Settling(threshold, tuple(times), tuple(ok))


def stationary_samples(v: np.ndarray, v_d: np.ndarray, speed: float = 1e-3) -> np.ndarray:
    """Mask of samples where both the arm and its reference are (nearly) still."""
    return (np.max(np.abs(v), axis=1) < speed) & (np.max(np.abs(v_d), axis=1) < STILL_SPEED)
