"""``perception.png``: what the estimator saw and how far off it was.

Left: the first perception camera's last colour image, each cube's estimated outline
drawn over it (its twelve edges projected through the camera). Right: every estimate's
position error against the simulator's truth over the run, per cube (a carried estimate
hollow). Drawn with matplotlib's object API (no pyplot).
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from cake_drake.perception.estimator import view_of
from cake_drake.perception.fit import HALF
from cake_drake.world.scene import cube_colours

#: The cube's twelve edges, as pairs of corner indices (corners: the sign patterns).
CORNERS = np.array(list(itertools.product((-1, 1), repeat=3)), float) * HALF
EDGES = [(i, j) for i, j in itertools.combinations(range(8), 2)
         if np.count_nonzero(CORNERS[i] != CORNERS[j]) == 1]  # fmt: skip


def outline(X_WB, camera) -> list[np.ndarray]:
    """The estimated cube's edges in the image of ``camera`` (world-fixed), as (2, 2)
    arrays of pixel coordinates."""
    view = view_of(camera)
    p_W = X_WB.multiply(CORNERS.T).T
    p_C = view.X_PC.inverse().multiply(p_W.T).T
    if (p_C[:, 2] <= 0.01).any():
        return []
    uv = view.intrinsics.project(p_C) + 0.5  # pixel u spans [u, u + 1] in the image
    return [uv[[i, j]] for i, j in EDGES]


def perception_figure(record: dict) -> Figure:
    s = record["summary"]
    fig = Figure(figsize=(11, 4.2), dpi=100)
    ax_img, ax_err = fig.add_axes((0.01, 0.08, 0.5, 0.84)), fig.add_axes((0.58, 0.14, 0.4, 0.76))
    image, camera = record["image"], record["camera"]
    ax_img.imshow(image, extent=(0, image.shape[1], image.shape[0], 0))
    names = sorted({r["cube"] for r in record["rows"]} | set(record["estimates"]))
    colours = {n: rgb for n, (_, rgb) in cube_colours(names).items()}
    drawn = []
    for name, X in record["estimates"].items():
        for edge in outline(X, camera):
            ax_img.plot(edge[:, 0], edge[:, 1], color="white", linewidth=2.2)
            ax_img.plot(edge[:, 0], edge[:, 1], color=colours[name], linewidth=1.0)
            drawn.append(edge)
    h, w = image.shape[:2]
    x0, y0, x1, y1 = 0, 0, w, h
    if drawn:  # zoomed onto the cubes, at the image's aspect
        pts = np.vstack(drawn)
        (cx, cy), half = pts.mean(axis=0), max(np.ptp(pts[:, 0]) / 2 + 20, 40)
        half_h = max(half * h / w, np.ptp(pts[:, 1]) / 2 + 20)
        half = max(half, half_h * w / h)
        x0, x1 = max(0, cx - half), min(w, cx + half)
        y0, y1 = max(0, cy - half * h / w), min(h, cy + half * h / w)
    ax_img.set_xlim(x0, x1)
    ax_img.set_ylim(y1, y0)
    ax_img.axis("off")
    ax_img.set_title(f"camera {camera.name}, the last frame: each cube's estimate outlined",
                     fontsize=9)  # fmt: skip
    for name in names:
        rows = [r for r in record["rows"] if r["cube"] == name]
        for seen, marker in ((True, "o"), (False, "o")):
            pick = [r for r in rows if r["seen"] == seen]
            if pick:
                ax_err.plot([r["t"] for r in pick], [r["position_mm"] for r in pick], marker,
                            markersize=4, color=colours[name],
                            markerfacecolor=colours[name] if seen else "none",
                            label=name if seen else None)  # fmt: skip
    pos = s["position_mm"]
    ax_err.set_xlabel("time (s)")
    ax_err.set_ylabel("position error (mm)")
    top = max([r["position_mm"] for r in record["rows"]], default=1.0)
    ax_err.set_ylim(0, max(1.0, 1.1 * top))
    ax_err.grid(alpha=0.3)
    ax_err.legend(fontsize=7, ncol=max(1, math.ceil(len(names) / 6)), loc="upper right")
    median = "-" if pos["median"] is None else f"{pos['median']:.2f}"
    p95 = "-" if pos["p95"] is None else f"{pos['p95']:.2f}"
    ax_err.set_title(
        f"{s['estimator']} estimator, depth noise {s['noise']}: {s['estimates']} estimates in "
        f"{s['frames']} frames\nposition error median {median} mm, p95 {p95} mm "
        "(filled: seen, hollow: carried)",
        fontsize=8.5,
    )
    return fig


def write_perception_figure(record: dict, path: str | Path) -> None:
    perception_figure(record).savefig(path)
