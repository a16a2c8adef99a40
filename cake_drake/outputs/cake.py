"""``cake.png``: the run's layers, each labelled classical or learned, on the world as
measured (the perception layer: the simulator's truth, or an estimator's cameras).

The chapter asks a student to draw a system's cake, "labeling each layer classical
or learned"; a run draws its own from ``summary.json``'s ``layers`` (see
:func:`cake_drake.outputs.report.layers`), so the same picture serves a run, the docs
and a notebook. Drawn with matplotlib's object API (no pyplot).
"""

from __future__ import annotations

import textwrap
from pathlib import Path

from matplotlib.figure import Figure
from matplotlib.patches import FancyBboxPatch

#: Top to bottom, as the cake is drawn.
LAYERS = ("symbolic", "geometric", "dynamic", "perception")
ROLE = {
    "symbolic": "what to do: the next ground action",
    "geometric": "where the hand goes: poses, IK, joint targets",
    "dynamic": "how hard the joints push: torques",
    "perception": "where things are: the world as measured",
}
COLOURS = {"classical": "#ecc98f", "learned": "#8fb4e8", "truth": "#d6d6d6"}
EDGES = {"classical": "#9c7434", "learned": "#355f9c", "truth": "#777777"}


def cake_figure(layers: dict, title: str = "") -> Figure:
    """The cake of ``layers`` (``{"symbolic": {"kind": ..., "what": ...}, ...}``)."""
    shown = [n for n in LAYERS if n in layers or n != "perception"]
    fig = Figure(figsize=(7.2, 1.2 + 1.13 * len(shown)), dpi=100)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(0, 10)
    ax.axis("off")
    widths = (5.8, 6.8, 7.8, 9.0)[-len(shown) :]  # tiers widen downwards, as a cake does
    height, gap, bottom = 1.5, 0.12, 0.35
    for k, name in enumerate(reversed(shown)):
        layer = layers.get(name) or {"kind": "classical", "what": "?"}
        kind = layer.get("kind", "classical")
        w = widths[len(shown) - 1 - k]
        x0, y0 = (10 - w) / 2, bottom + k * (height + gap)
        ax.add_patch(
            FancyBboxPatch(
                (x0, y0), w, height, boxstyle="round,pad=0,rounding_size=0.25",
                facecolor=COLOURS.get(kind, "#dddddd"), edgecolor=EDGES.get(kind, "#555555"),
                linewidth=1.6,
            )
        )  # fmt: skip
        ax.text(x0 + 0.25, y0 + height - 0.28, f"{name.upper()}  ·  {kind}", fontsize=11,
                fontweight="bold", va="center", ha="left", color="#222222")  # fmt: skip
        ax.text(x0 + w - 0.25, y0 + height - 0.28, ROLE[name], fontsize=7.5, va="center",
                ha="right", color="#444444", style="italic")  # fmt: skip
        # Characters a line holds inside the tier, its margins kept (monospace, 8.5 pt).
        what = "\n".join(textwrap.wrap(str(layer.get("what", "")), int((w - 0.5) * 10.5))[:3])
        ax.text(x0 + 0.25, y0 + height - 0.62, what, fontsize=8.5, va="top", ha="left",
                color="#222222", family="monospace")  # fmt: skip
    top = bottom + len(shown) * (height + gap)
    ax.text(5, top + 0.25, title or "the run's cake", fontsize=12, ha="center", va="center")
    ax.set_ylim(0, top + 0.55)
    for i, (kind, colour) in enumerate(COLOURS.items()):
        ax.add_patch(FancyBboxPatch((0.25 + i * 1.7, 0.05), 0.3, 0.2, boxstyle="square,pad=0",
                                    facecolor=colour, edgecolor=EDGES[kind]))  # fmt: skip
        ax.text(0.65 + i * 1.7, 0.15, kind, fontsize=8, va="center")
    return fig


def write_cake(layers: dict, path: str | Path, title: str = "") -> None:
    """Draw :func:`cake_figure` to a PNG at ``path``."""
    cake_figure(layers, title).savefig(path)
