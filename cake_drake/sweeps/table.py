"""The results table (``results.parquet`` and ``results.csv``) and the plots its axes call for.

One row per run: ``run_id``, ``index``, one column per parameter (the axis's dotted
path, ``seed``), the metrics of :data:`cake_drake.sweeps.worker.METRICS`, any columns the
collectors added, and ``folder`` (the run's outputs, relative to the sweep's folder).
Each numeric axis gets one figure: success rate, tracking error, plan length and run
time against it, one line per value of a second axis when there are two; a non-numeric
axis (a planner, an IK solver) gets the same four panels over its values.
"""

from __future__ import annotations

import csv
import math
import os
from collections import defaultdict
from pathlib import Path

from matplotlib.figure import Figure

from cake_drake.sweeps.worker import METRICS

PANELS = (
    ("success", "success rate [%]", "rate"),
    ("tracking_rms_mrad", "RMS tracking error [mrad]", "mean"),
    ("plan_length", "plan length [actions]", "mean"),
    ("wall_s", "wall time per run [s]", "mean"),
)


def column_order(rows: list[dict], params: list[str]) -> list[str]:
    cols = ["run_id", "index", *params, *METRICS]
    for row in rows:
        cols += [k for k in row if k not in cols and k != "folder"]
    return [*cols, "folder"]


def _normalise(values: list) -> list:
    """One type per column: numbers stay numbers (float if any is), anything mixed is text."""
    present = [v for v in values if v is not None]
    if all(isinstance(v, bool) for v in present):
        return values
    if all(isinstance(v, int | float) and not isinstance(v, bool) for v in present):
        if any(isinstance(v, float) for v in present):
            return [None if v is None else float(v) for v in values]
        return values
    return [None if v is None else str(v) for v in values]


def write_table(rows: list[dict], out: Path, columns: list[str], exact: bool = False) -> list[Path]:
    """``results.parquet`` and ``results.csv`` in ``out`` (each written whole, then moved in):
    a sweep's columns around ``columns`` (its axes), or with ``exact`` those alone."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    cols = list(columns) if exact else column_order(rows, columns)
    data = {c: _normalise([r.get(c) for r in rows]) for c in cols}
    table = pa.table({c: pa.array(v) for c, v in data.items()})
    parquet, text = out / "results.parquet", out / "results.csv"
    pq.write_table(table, out / ".results.parquet.part")
    os.replace(out / ".results.parquet.part", parquet)
    with open(out / ".results.csv.part", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(cols)
        for i in range(len(rows)):
            writer.writerow(["" if data[c][i] is None else data[c][i] for c in cols])
    os.replace(out / ".results.csv.part", text)
    return [parquet, text]


def read_table(path: str | Path) -> list[dict]:
    """The rows of a ``results.parquet``, as dicts."""
    import pyarrow.parquet as pq

    return pq.read_table(path).to_pylist()


def _numeric(values: list) -> bool:
    return all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)


def _aggregate(rows: list[dict], metric: str, how: str) -> float:
    if how == "rate":
        return 100.0 * sum(bool(r.get("success")) for r in rows) / len(rows) if rows else math.nan
    values = [r[metric] for r in rows if r.get("status") == "done" and r.get(metric) is not None]
    return sum(values) / len(values) if values else math.nan


def write_plots(
    rows: list[dict], folder: Path, axes: list[str], series: str | None = None
) -> list[Path]:
    """One figure per axis that varies (seeds are averaged over, never plotted); one line
    per value of ``series`` (the cases), or else of the other axis when there are two."""
    varying = [a for a in axes if a != "seed" and _distinct(rows, a) > 1]
    if series is not None and (series in varying or not 1 < _distinct(rows, series) <= 8):
        series = None
    written = []
    for axis in varying:
        others = [a for a in varying if a != axis]
        lines = series
        if lines is None and len(others) == 1 and _distinct(rows, others[0]) <= 6:
            lines = others[0]
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"{axis}.png"
        axis_figure(rows, axis, lines).savefig(path, dpi=100)
        written.append(path)
    return written


def _key(value) -> str:
    return repr(value)


def _distinct(rows: list[dict], axis: str) -> int:
    return len({_key(r.get(axis)) for r in rows})


def axis_figure(rows: list[dict], axis: str, series: str | None = None) -> Figure:
    """Success rate, tracking error, plan length and run time against ``axis``: a numeric
    axis as a line over its values; a categorical one (a planner, a controller) as one
    marker per category, in the order the sweep file lists them, unconnected."""
    xs = list({_key(r.get(axis)): r.get(axis) for r in rows}.values())  # file order
    numeric = _numeric(xs)
    if numeric:
        xs.sort(key=_sort_key)
    groups: dict[str, list[dict]] = defaultdict(list)
    for r in rows:
        groups[_key(r.get(series)) if series else ""].append(r)
    fig = Figure(figsize=(11, 7))
    panels = fig.subplots(2, 2).ravel()
    for ax, (metric, label, how) in zip(panels, PANELS, strict=True):
        for members in sorted(groups.values(), key=lambda m: _sort_key(m[0].get(series))):
            ys = [
                _aggregate([r for r in members if _key(r.get(axis)) == _key(x)], metric, how)
                for x in xs
            ]
            pos = xs if numeric else list(range(len(xs)))
            legend = f"{series} = {members[0].get(series)}" if series else None
            ax.plot(pos, ys, marker="o", lw=1.2 if numeric else 0, label=legend)
        if not numeric:
            ax.set_xticks(range(len(xs)), [str(x) for x in xs], rotation=20, fontsize=8)
            ax.set_xlim(-0.5, len(xs) - 0.5)
        ax.set_xlabel(axis)
        ax.set_ylabel(label)
        if how == "rate":
            ax.set_ylim(-5, 105)
        ax.grid(alpha=0.3)
        if series:
            ax.legend(fontsize=8)
    n = len(rows)
    fig.suptitle(f"{n} runs: success, tracking, plan length and run time against {axis}")
    fig.tight_layout(rect=(0, 0, 1, 0.96))
    return fig


def _sort_key(value):
    if isinstance(value, int | float) and not isinstance(value, bool):
        return (0, value, "")
    return (1, 0, str(value))
