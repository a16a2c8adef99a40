"""Plots from the loggers: joint 4's position, reference and torque, phases shaded.

Figures are made with matplotlib's object API (no pyplot), so plotting neither needs
nor changes a GUI backend: the CLI writes PNGs headless, and a notebook can display
the returned :class:`~matplotlib.figure.Figure` inline.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from cake_drake.formats import PHASE_NAMES

PHASE_COLOURS = {
    "pre-grasp": "#dbe9f6",
    "grasp": "#f6e3c5",
    "lift": "#f8d0d0",
    "transport": "#e3d3ef",
    "place": "#d3ecd3",
    "retract": "#ececec",
}


def phase_spans(t: np.ndarray, phase: np.ndarray) -> list[tuple[float, float, str]]:
    """Contiguous (start, end, phase name) runs, idle left out."""
    spans = []
    start = 0
    for i in range(1, len(t) + 1):
        if i == len(t) or phase[i] != phase[start]:
            name = PHASE_NAMES[int(phase[start])]
            if name != "idle":
                spans.append((float(t[start]), float(t[min(i, len(t) - 1)]), name))
            start = i
    return spans


def shade_phases(ax, spans) -> None:
    """Shade each phase's time spans in its colour, behind the data (one artist a phase)."""
    from matplotlib.collections import PolyCollection

    transform = ax.get_xaxis_transform()  # x in data, y in axes fraction
    for name, colour in PHASE_COLOURS.items():
        boxes = [[(t0, 0), (t1, 0), (t1, 1), (t0, 1)] for t0, t1, n in spans if n == name]
        if boxes:
            ax.add_collection(
                PolyCollection(
                    boxes, facecolors=colour, linewidths=0, zorder=0, transform=transform
                ),
                autolim=False,
            )


def phase_key(fig: Figure) -> None:
    """A one-row key of the phase colours along the top of ``fig``."""
    from matplotlib.patches import Patch

    handles = [Patch(color=c, label=n) for n, c in PHASE_COLOURS.items()]
    fig.legend(
        handles=handles,
        loc="upper center",
        ncol=6,
        fontsize=8,
        frameon=False,
        bbox_to_anchor=(0.5, 0.955),
    )


def joint_figure(joint: int = 4, drawn: bool = False) -> tuple[Figure, Sequence]:
    """The joint plot's figure before its data: three panels, their labels, the phase
    key and the margins. ``drawn`` draws it once, empty, to an Agg canvas: matplotlib
    then has its tick and text objects made, and the data pass (:func:`joint_plot` with
    ``figure``) draws the same PNG byte for byte in about two thirds of the time. A run's
    plot helper prepares one while the simulation runs."""
    fig = Figure(figsize=(11, 7.5))
    axes = fig.subplots(3, 1, sharex=True, gridspec_kw={"height_ratios": [3, 2, 3]})
    axes[0].set_ylabel(f"joint {joint} angle [rad]")
    axes[1].set_ylabel("q − q_d [mrad]")
    axes[2].set_ylabel(f"joint {joint} torque [N·m]")
    axes[2].set_xlabel("time [s]")
    phase_key(fig)
    # Fixed margins rather than tight_layout: that would draw the whole figure once more.
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.07, top=0.91, hspace=0.12)
    if drawn:
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        FigureCanvasAgg(fig).draw()
    return fig, axes


def joint_plot(
    t: np.ndarray,
    q: np.ndarray,
    q_d: np.ndarray,
    tau: np.ndarray,
    phase: np.ndarray,
    path: str | Path | None = None,
    joint: int = 4,
    title: str = "",
    tau_label: str = "τ commanded",
    extra_tau: Sequence[tuple[np.ndarray, str]] = (),
    marks: Sequence[tuple[float, str]] = (),
    faults: Sequence[tuple[float, str]] = (),
    figure: tuple[Figure, Sequence] | None = None,
) -> Figure:
    """Three panels for one joint (1-based): q and q_d, tracking error, torque.

    ``marks`` are (time, label) of the monitor's events (replans, repeats, skips), and
    ``faults`` of the faults that struck (a knock, a move, a slip): a vertical line
    through every panel (purple dotted and red dash-dot), labelled on the top one. Saved
    to ``path`` when given; the figure is returned either way. ``figure`` is one made by
    :func:`joint_figure` for the same joint and not used yet (else a new one is made).
    """
    j = joint - 1
    spans = phase_spans(t, phase)
    fig, axes = figure if figure is not None else joint_figure(joint)
    ax = axes[0]
    shade_phases(ax, spans)
    ax.plot(t, q_d[:, j], color="k", lw=1.2, ls="--", label="q_d (reference)")
    ax.plot(t, q[:, j], color="tab:blue", lw=1.0, label="q (measured)")
    ax.legend(loc="lower right", fontsize=8)
    ax = axes[1]
    shade_phases(ax, spans)
    ax.plot(t, (q[:, j] - q_d[:, j]) * 1000, color="tab:red", lw=0.9)
    ax.axhline(0, color="k", lw=0.5)
    ax = axes[2]
    shade_phases(ax, spans)
    ax.plot(t, tau[:, j], color="tab:green", lw=1.0, label=tau_label)
    for series, label in extra_tau:
        ax.plot(t, series[:, j], lw=0.8, alpha=0.8, label=label)
    ax.legend(loc="lower right", fontsize=8)
    lines = [(w, lb, "tab:purple", ":", -10) for w, lb in marks]
    lines += [(w, lb, "tab:red", "-.", -22) for w, lb in faults]
    for when, label, colour, style, dy in lines:
        for a in axes:
            a.axvline(when, color=colour, lw=1.2, ls=style)
        axes[0].annotate(
            label, (when, 1.0), xycoords=("data", "axes fraction"), xytext=(2, dy),
            textcoords="offset points", fontsize=8, color=colour,
        )  # fmt: skip
    if title:
        fig.suptitle(title, y=0.99, fontsize=11)
    if path is not None:
        # Light PNG compression: a third faster to write, a sixth larger.
        fig.savefig(Path(path), dpi=100, pil_kwargs={"compress_level": 1})
    return fig
