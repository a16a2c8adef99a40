"""The estimator's error log, measured against the simulator's truth after the run.

The estimator never reads the truth; the run logs every cube's true state at each step
beside it, and each estimate is compared with the truth at its own time here: position
error in mm, yaw error in degrees modulo 90 (a cube looks the same turned a quarter).
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RotationMatrix


def _yaw(R: np.ndarray) -> float:
    return math.atan2(R[1, 0], R[0, 0])


def yaw_error_deg(R_est: np.ndarray, R_true: np.ndarray) -> float:
    """The yaw between two cube orientations, modulo 90 degrees (0 to 45)."""
    d = math.degrees(_yaw(R_est) - _yaw(R_true)) % 90.0
    return min(d, 90.0 - d)


def _stats(values) -> dict:
    if not len(values):
        return {"median": None, "p95": None, "max": None}
    v = np.asarray(values, float)
    return {
        "median": round(float(np.median(v)), 3),
        "p95": round(float(np.percentile(v, 95)), 3),
        "max": round(float(v.max()), 3),
    }


def truth_at(truth: dict, name: str, t: float) -> tuple[np.ndarray, np.ndarray]:
    """A cube's true (position, rotation matrix) at time ``t`` from its logged state
    (``truth[name] = (times, rows)``, a row the free body's [qw qx qy qz x y z ...])."""
    times, rows = truth[name]
    k = int(np.clip(np.searchsorted(times, t - 1e-9), 0, len(times) - 1))
    q = rows[k, :4]
    R = RotationMatrix(Quaternion(q / np.linalg.norm(q))).matrix()
    return rows[k, 4:7], R


def errors(log, truth: dict) -> list[dict]:
    """One row per estimate in ``log`` ((t, cube, X_WB, seen now)): its errors."""
    rows = []
    for t, name, X, seen in log:
        p, R = truth_at(truth, name, t)
        err = float(np.linalg.norm(X.translation() - p)) * 1000
        rows.append({
            "t": t, "cube": name, "seen": seen, "position_mm": err,
            "yaw_deg": yaw_error_deg(X.rotation().matrix(), R),
        })  # fmt: skip
    return rows


def summarize(rows: list[dict], frames: int, unknown: list[str]) -> dict:
    """``summary.json``'s ``perception`` figures from :func:`errors`' rows."""
    cubes = sorted({r["cube"] for r in rows})
    seen = [r for r in rows if r["seen"]]
    return {
        "frames": frames,
        "estimates": len(rows),
        "seen": len(seen),
        "carried": len(rows) - len(seen),
        "position_mm": _stats([r["position_mm"] for r in rows]),
        "yaw_deg": _stats([r["yaw_deg"] for r in rows]),
        "seen_position_mm": _stats([r["position_mm"] for r in seen]),
        "per_cube": {
            c: {
                "estimates": sum(r["cube"] == c for r in rows),
                **_stats([r["position_mm"] for r in rows if r["cube"] == c]),
            }
            for c in cubes
        },  # fmt: skip
        "unknown": list(unknown),
    }
