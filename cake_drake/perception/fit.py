"""A cube's pose from the points seen on it: a start from the points' footprint, then
ICP against the cube's six faces.

The cube's surface has a closed-form closest point, so each ICP step pairs every point
with the exact nearest point of the model (no sampled model, no KD tree) and solves the
point-to-plane step in closed form (a 6 x 6 least-squares system): NumPy is enough.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix

from cake_drake.world.scene import CUBE_SIZE

HALF = CUBE_SIZE / 2
#: m: a point this close to the fitted cube's surface is an inlier (noise-free depth;
#: with noise, :func:`fit_cube`'s ``tol`` widens it).
INLIER_TOL = 0.003
#: A cube is seen when at least this many of its points are inliers.
MIN_INLIERS = 20
ICP_ITERATIONS = 30
#: The ICP step's damping, per point, and its largest move (m): the fixed point is the
#: undamped one, only the way there is shorter-stepped.
DAMPING = 1e-3
MAX_STEP = 0.01
#: m: how far from the median of a cube's points a point of the cube can be (the centre
#: to a corner is 3.5 cm; the median may sit a centimetre off the centre).
REACH = 0.05


@dataclass(frozen=True)
class Fit:
    """A fitted pose, how many points agree with it, their RMS distance (m), and how
    many of them lie on the cube's upward face (0: its top is hidden)."""

    X_WB: RigidTransform
    inliers: int
    rms: float
    top: int = 0


def closest_on_cube(p: np.ndarray, half: float = HALF) -> tuple[np.ndarray, np.ndarray]:
    """For points in the cube's frame (N, 3): the nearest surface points and the surface
    normals there (outward unit vectors)."""
    d = np.abs(p) - half
    axis = d.argmax(axis=1)
    rows = np.arange(len(p))
    inside = d[rows, axis] <= 0
    q = np.clip(p, -half, half)
    sign = np.where(p[rows, axis] >= 0, 1.0, -1.0)
    q[inside, axis[inside]] = sign[inside] * half
    n = np.zeros_like(p)
    n[rows, axis] = sign
    out = ~inside
    diff = p[out] - q[out]
    length = np.linalg.norm(diff, axis=1, keepdims=True)
    n[out] = np.where(length > 1e-12, diff / np.maximum(length, 1e-12), n[out])
    return q, n


def _rotation(w: np.ndarray) -> np.ndarray:
    angle = float(np.linalg.norm(w))
    if angle < 1e-12:
        return np.eye(3)
    k = w / angle
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def icp(
    points: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    tol: float = INLIER_TOL,
    iterations: int = ICP_ITERATIONS,
):
    """Point-to-plane ICP of world points onto the cube at (R, t); returns (R, t, the
    points' distances to the surface). Points farther from the surface than 1 cm (the
    first steps) or twice ``tol`` (the rest) are left out of a step."""
    R, t = R.copy(), t.copy()
    for k in range(iterations):
        p = (points - t) @ R  # in the cube's frame
        q, n = closest_on_cube(p)
        r = np.einsum("ij,ij->i", n, p - q)
        use = np.abs(r) < (max(0.01, 2 * tol) if k < 3 else max(0.005, 2 * tol))
        if use.sum() < 6:
            break
        J = np.hstack([n[use], np.cross(p[use], n[use])])
        # Damped (a side-only view leaves the height nearly free: an undamped step there
        # can leave the cube), the damping a metre and a radian of a cube's size apart.
        H = J.T @ J + DAMPING * len(J) * np.diag([1.0, 1.0, 1.0, HALF**2, HALF**2, HALF**2])
        x = np.linalg.solve(H, J.T @ r[use])
        x[:3] *= min(1.0, MAX_STEP / max(float(np.linalg.norm(x[:3])), 1e-12))
        R = R @ _rotation(x[3:])
        t = t + R @ x[:3]
        if np.linalg.norm(x[:3]) < 1e-7 and np.linalg.norm(x[3:]) < 1e-6:
            break
    u, _, vt = np.linalg.svd(R)
    R = u @ vt
    p = (points - t) @ R
    q, _ = closest_on_cube(p)
    return R, t, np.linalg.norm(p - q, axis=1)


def _yaw_R(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def footprint_start(points: np.ndarray, viewpoint: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A first (R, t) from the points alone: the yaw and centre of the smallest rectangle
    round the points seen from above (a top face, or the L of two side faces), the
    height from the top face or the sides' extent. Where only one face shows (a thin
    rectangle), the centre is put half a cube behind it, away from ``viewpoint``."""
    xy = points[:, :2]
    best = None
    for deg in np.arange(0.0, 90.0, 2.0):
        a = math.radians(deg)
        c, s = math.cos(a), math.sin(a)
        u = xy @ np.array([[c, -s], [s, c]])
        lo, hi = u.min(axis=0), u.max(axis=0)
        area = float(np.prod(hi - lo))
        if best is None or area < best[0]:
            best = (area, a, lo, hi)
    _, a, lo, hi = best
    c, s = math.cos(a), math.sin(a)
    axes = np.array([[c, s], [-s, c]])  # rows: the rectangle's axes in the world
    mid = (lo + hi) / 2
    for i in range(2):  # a side shorter than the cube: its hidden part is behind it
        if hi[i] - lo[i] < CUBE_SIZE - 0.004:
            toward = float(axes[i] @ (viewpoint[:2] - axes.T @ mid))
            mid[i] += -np.sign(toward) * (HALF - (hi[i] - lo[i]) / 2)
    centre_xy = axes.T @ mid
    z_top, z_low = float(points[:, 2].max()), float(points[:, 2].min())
    top = points[:, 2] > z_top - 0.003
    if top.sum() >= 10 and z_top - z_low < CUBE_SIZE - 0.004:
        z = z_top - HALF
    elif z_top - z_low >= CUBE_SIZE - 0.004:
        z = (z_top + z_low) / 2
    else:
        z = z_top - HALF
    return _yaw_R(a), np.array([centre_xy[0], centre_xy[1], z])


#: The 24 rotations that map a cube onto itself.
SYMMETRIES = tuple(
    np.array(m, float)
    for m in (
        np.diag(signs) @ np.eye(3)[list(perm)]
        for perm in itertools.permutations(range(3))
        for signs in itertools.product((1, -1), repeat=3)
    )
    if np.linalg.det(m) > 0
)


def canonical(R: np.ndarray, yaw_ref: float) -> np.ndarray:
    """Of the 24 rotations that put the cube where ``R`` does, the one whose z axis is
    nearest world up and, among those, whose yaw is nearest ``yaw_ref``."""
    best, key = R, None
    for S in SYMMETRIES:
        Q = R @ S
        yaw = math.atan2(Q[1, 0], Q[0, 0])
        off = abs((yaw - yaw_ref + math.pi) % (2 * math.pi) - math.pi)
        k = (round(-Q[2, 2], 6), off)
        if key is None or k < key:
            best, key = Q, k
    return best


def _score(dist: np.ndarray, tol: float) -> tuple[int, float]:
    """Inliers first, then the RMS distance (capped, so that outliers count alike)."""
    return int((dist < tol).sum()), -float(np.sqrt(np.mean(np.minimum(dist, 0.01) ** 2)))


def fit_cube(
    points: np.ndarray,
    viewpoint: np.ndarray,
    start: RigidTransform | None = None,
    tol: float = INLIER_TOL,
) -> Fit | None:
    """The cube's pose from its world points (N, 3), or None where too few agree with any
    pose. ``start`` (the last estimate) is tried first; the points' own footprint too,
    and the better fit kept. ``tol`` (m) is the inlier distance: wider for noisy depth.
    The yaw is given as the one of the cube's four nearest the start's (or the cube's
    bearing from the robot's base: a cube faces the robot)."""
    # A few pixels elsewhere of the cube's colour (a highlight, a sliver of another cube's
    # shade) are not the cube: only points within a cube's reach of the median are fitted.
    points = points[np.linalg.norm(points - np.median(points, axis=0), axis=1) < REACH]
    if len(points) < MIN_INLIERS:
        return None
    best = None
    if start is not None:  # where the cube was: kept if nearly every point agrees
        R, t, dist = icp(points, start.rotation().matrix(), start.translation(), tol)
        best = (_score(dist, tol), R, t, dist)
    if best is None or best[0][0] < 0.9 * len(points):
        R, t, dist = icp(points, *footprint_start(points, viewpoint), tol)
        if best is None or _score(dist, tol) > best[0]:
            best = (_score(dist, tol), R, t, dist)
    (inliers, _), R, t, dist = best
    if inliers < MIN_INLIERS:
        return None
    if start is not None:
        R_start = start.rotation().matrix()
        yaw_ref = math.atan2(R_start[1, 0], R_start[0, 0])
    else:
        yaw_ref = math.atan2(t[1], t[0])
    R = canonical(R, yaw_ref)
    rms = float(np.sqrt(np.mean(dist[dist < tol] ** 2)))
    p = (points - t) @ R
    on_top = (p[:, 2] > HALF - tol) & (np.abs(p[:, :2]) < HALF).all(axis=1) & (dist < tol)
    return Fit(RigidTransform(RotationMatrix(R), t), inliers, rms, int(on_top.sum()))


#: m: a cube whose top is hidden and whose bottom is this close to the top of what is
#: below it (the table, a cube) rests on it.
SETTLE_TOL = 0.005
#: Points on the upward face that make its height a measurement of its own.
TOP_SEEN = 10
#: rad: a resting cube fitted tilted less than this is level (half the facts' TILT_TOL).
LEVEL_TOL = 0.05


def settle(fits: dict[str, Fit], others: dict[str, RigidTransform]) -> dict[str, Fit]:
    """``fits`` with each cube that rests on something set on it: the table (z = 0) or
    a cube below it (``others`` included: estimates carried from earlier frames), within
    :data:`SETTLE_TOL`. Such a cube is level (its fitted tilt, under :data:`LEVEL_TOL`, is
    the noise's), and one whose top face is hidden (a tower's lower cubes: only their
    sides show, and a side says little of its height) takes its height from its support.
    Lowest first, so a tower settles from the table up; a cube that rests on nothing
    (held, falling) or tilts further is left as fitted."""
    out = dict(fits)
    placed = {n: X for n, X in others.items() if n not in fits}
    for name in sorted(fits, key=lambda n: fits[n].X_WB.translation()[2]):
        fit = fits[name]
        p = fit.X_WB.translation()
        R = fit.X_WB.rotation().matrix()
        bottom = p[2] - HALF
        supports = [0.0] + [
            X.translation()[2] + HALF
            for other, X in placed.items()
            if np.linalg.norm(X.translation()[:2] - p[:2]) < HALF
        ]
        near = [z for z in supports if abs(bottom - z) < SETTLE_TOL]
        tilt = math.acos(float(np.clip(R[2, 2], -1.0, 1.0)))
        if near and tilt < LEVEL_TOL:
            z = max(near) + HALF if fit.top < TOP_SEEN else p[2]
            level = RotationMatrix(_yaw_R(math.atan2(R[1, 0], R[0, 0])))
            fit = Fit(RigidTransform(level, [p[0], p[1], z]), fit.inliers, fit.rms, fit.top)
            out[name] = fit
        placed[name] = fit.X_WB
    return out
