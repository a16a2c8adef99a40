"""From images to points: depth back-projected through the camera's intrinsics, cubes
found by their colours, and the depth sensor's noise.

Drake's ``CameraInfo`` gives the principal point as ``(width / 2 - 0.5, height / 2 - 0.5)``,
the centre of the image if pixel ``u`` is centred at ``u``; the renderer (VTK) samples pixel
``u`` at ``u + 0.5`` instead, so pixel ``(u, v)`` (column, row) looks along
``((u + 0.5 - cx) / fx, (v + 0.5 - cy) / fy, 1)`` in the camera frame (+z forward, +x right,
+y down). Read with ``u - cx``, every point is half a pixel off (0.9 mm at 1 m for a
640 x 480 camera of 45 degrees); a test holds the convention against a cube at a known pose.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: A pixel is a cube's when its colour's saturation and brightness are at least these and
#: its chromaticity is nearest that cube's, within :data:`CHROMA_TOL`.
MIN_SATURATION = 0.4
MIN_VALUE = 0.08
CHROMA_TOL = 0.06
#: Where the renderer samples pixel ``u`` (see the module's docstring).
PIXEL_CENTRE = 0.5


@dataclass(frozen=True)
class Intrinsics:
    """A pinhole camera: image size and focal lengths in pixels, principal point."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @classmethod
    def of(cls, info) -> Intrinsics:
        """From a ``pydrake.systems.sensors.CameraInfo``."""
        return cls(
            info.width(), info.height(), info.focal_x(), info.focal_y(),
            info.center_x(), info.center_y(),
        )  # fmt: skip

    def project(self, p_C: np.ndarray) -> np.ndarray:
        """(N, 2) pixel coordinates (u, v) of camera-frame points (N, 3)."""
        p = np.atleast_2d(p_C)
        z = p[:, 2]
        u = self.fx * p[:, 0] / z + self.cx - PIXEL_CENTRE
        v = self.fy * p[:, 1] / z + self.cy - PIXEL_CENTRE
        return np.column_stack([u, v])


def back_project(depth: np.ndarray, intr: Intrinsics, rows: np.ndarray, cols: np.ndarray):
    """Camera-frame points (N, 3) of the pixels at ``rows``, ``cols`` of a depth image (m,
    along the optical axis); pixels without a finite positive depth are dropped."""
    z = depth[rows, cols].astype(float)
    keep = np.isfinite(z) & (z > 0)
    z = z[keep]
    u, v = cols[keep] + PIXEL_CENTRE, rows[keep] + PIXEL_CENTRE
    return np.column_stack([(u - intr.cx) * z / intr.fx, (v - intr.cy) * z / intr.fy, z])


def noisy_depth(depth: np.ndarray, sigma_at: float, growth: float, rng) -> np.ndarray:
    """``depth`` with axial Gaussian noise of sigma ``sigma_at + growth (z - 0.4)^2`` m
    (Nguyen et al. 2012: 1.2 mm at 0.4 m); pixels without depth stay without."""
    z = depth.astype(np.float32, copy=True)
    ok = np.isfinite(z) & (z > 0)
    sigma = sigma_at + growth * (z[ok] - 0.4) ** 2
    z[ok] += (rng.standard_normal(sigma.shape) * sigma).astype(np.float32)
    return z


def chromaticity(rgb: np.ndarray) -> np.ndarray:
    """(..., 3) colours (any scale) as chromaticity r/s, g/s, b/s: brightness cancels."""
    rgb = np.asarray(rgb, float)
    s = rgb.sum(axis=-1, keepdims=True)
    return rgb / np.maximum(s, 1e-9)


def segment(rgb: np.ndarray, colours: Sequence[Sequence[float]]) -> np.ndarray:
    """(H, W) int: the index of the cube colour each pixel shows, -1 for none.

    A cube's faces are lit differently, so a pixel is compared by chromaticity, and only
    saturated, lit pixels count (the table, the robot and shadows are not saturated).
    Colour and depth come from one camera at one size, each pixel one ray, so a pixel on
    a cube's outline is the cube's in both images: none is dropped."""
    img = np.asarray(rgb[..., :3])
    r, g, b = img[..., 0], img[..., 1], img[..., 2]  # channel by channel: faster than axis=-1
    hi = np.maximum(np.maximum(r, g), b).astype(np.int16)
    lo = np.minimum(np.minimum(r, g), b).astype(np.int16)
    lit = (hi >= MIN_VALUE * 255) & ((hi - lo) >= MIN_SATURATION * hi)
    rows, cols = np.nonzero(lit)
    labels = np.full(lit.shape, -1, np.int32)
    if len(rows):
        chroma = chromaticity(img[rows, cols].astype(np.float32))
        ref = chromaticity(np.asarray(colours, np.float32))
        dist = ((chroma[:, None, :] - ref[None, :, :]) ** 2).sum(axis=-1)
        best = dist.argmin(axis=1)
        ok = dist[np.arange(len(best)), best] <= CHROMA_TOL**2
        labels[rows[ok], cols[ok]] = best[ok]
    return labels
