"""Run a sweep: expand it, hand the runs to an engine, keep every answer, write the table.

The output folder holds ``sweep.yaml`` (the file as given), ``runs/<id>/`` per run (its
outputs, the resolved ``scenario.yaml`` that re-runs it alone with ``python -m
cake_drake.run --scenario``, and ``row.json``), ``results.parquet`` and ``results.csv``
(one row per run) and ``plots/``. A row is written as soon as its run ends, so an
interrupted sweep keeps what finished and ``resume=True`` runs only the rest.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from cake_drake.errors import InputError
from cake_drake.sweeps.spec import Sweep, run_id
from cake_drake.sweeps.table import write_plots, write_table

#: Statuses a resumed sweep does not run again (a crashed run is tried again).
FINISHED = ("done", "failed")


@dataclass
class SweepResult:
    """The rows (in run order) and where they were written."""

    out: Path
    rows: list[dict]
    total: int
    interrupted: bool = False
    skipped: int = 0  # finished before, kept by resume
    written: list[Path] = field(default_factory=list)

    def count(self, status: str) -> int:
        return sum(r["status"] == status for r in self.rows)


class SweepProgress:
    """``sweep [####......] 12/30  done 10  failed 2  running 2  ETA 0:41`` on stderr."""

    def __init__(self, total: int, finished: int, enabled: bool = True) -> None:
        self.total, self.enabled = total, enabled
        self.done = self.failed = 0
        self.before = finished
        self.running: set[str] = set()
        self.t0 = time.perf_counter()
        self.tty = sys.stderr.isatty()

    def event(self, kind: str, job: dict, row: dict | None = None) -> None:
        if kind == "start":
            self.running.add(job["id"])
        elif kind == "queued":
            self.running.discard(job["id"])
        else:
            self.running.discard(job["id"])
            if row["status"] == "done":
                self.done += 1
            else:
                self.failed += 1
        if self.enabled and (self.tty or kind == "done"):
            self._draw(job if kind == "done" else None, row)

    def line(self) -> str:
        finished = self.before + self.done + self.failed
        frac = finished / self.total if self.total else 1.0
        bar = "#" * int(20 * frac) + "." * (20 - int(20 * frac))
        ran = self.done + self.failed
        left = self.total - finished
        if ran and left:
            eta = (time.perf_counter() - self.t0) / ran * left
            eta_text = f"ETA {int(eta // 60)}:{int(eta % 60):02d}"
        else:
            eta_text = "ETA -:--" if left else "finished"
        return (
            f"sweep [{bar}] {finished}/{self.total}  done {self.before + self.done}  "
            f"failed {self.failed}  running {len(self.running)}  {eta_text}"
        )

    def _draw(self, job: dict | None, row: dict | None) -> None:
        if self.tty:
            print("\r" + self.line().ljust(90), end="", file=sys.stderr, flush=True)
        else:
            what = f"  ({job['id']}: {row['status']})" if job and row else ""
            print(self.line() + what, file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.enabled and self.tty:
            print(file=sys.stderr, flush=True)


def prepare(sweep: Sweep, out: Path) -> list[dict]:
    """Every run as a job for the engines: id, index, parameters, scenario text, collectors."""
    from pydrake.common.yaml import yaml_dump_typed

    jobs = []
    for run in sweep.runs():
        run.id = run_id(run, sweep.collect)
        run.scenario.outputs.folder = str((out / "runs" / run.id).resolve())
        jobs.append(
            {
                "id": run.id,
                "index": run.index,
                "params": run.params,
                "scenario": yaml_dump_typed(run.scenario),
                "collect": list(sweep.collect),
            }
        )
    return jobs


def _rows_on_disk(out: Path) -> dict[str, dict]:
    rows = {}
    for path in sorted((out / "runs").glob("*/row.json")):
        try:
            row = json.loads(path.read_text())
        except (OSError, ValueError, UnicodeDecodeError):
            continue  # a row cut short: the run counts as not finished
        if not isinstance(row, dict) or not {"run_id", "status"} <= row.keys():
            continue  # not a row this sweep wrote: the run is run again
        rows[path.parent.name] = row
    return rows


def _keep(out: Path, job: dict, answer: dict) -> dict:
    """Write a finished run's files and row into ``runs/<id>/`` (row last, atomically)."""
    row = {"run_id": job["id"], "index": job["index"], **job["params"]}
    row.update({k: v for k, v in answer["row"].items() if k != "run_id"})
    row["folder"] = f"runs/{job['id']}"
    folder = out / "runs" / job["id"]
    folder.mkdir(parents=True, exist_ok=True)
    for name, data in answer["files"].items():
        tmp = folder / f".{name}.part"
        tmp.write_bytes(data)
        os.replace(tmp, folder / name)
    tmp = folder / ".row.json.part"
    tmp.write_text(json.dumps(row, indent=1) + "\n")
    os.replace(tmp, folder / "row.json")
    return row


#: What a sweep writes into its folder (each run's outputs in runs/<id>/).
SWEEP_OUTPUTS = ("sweep.yaml", "results.parquet", "results.csv", "plots", "runs")


def run_sweep(
    sweep: Sweep, out: str | Path, engine, resume: bool = False, progress: bool = True
) -> SweepResult:
    """Run every run of ``sweep`` on ``engine`` (:class:`LocalPool` or :class:`RayCluster`)
    into ``out``; a run that fails or crashes is a row, and Ctrl-C keeps what finished."""
    from cake_drake.outputs.files import check_output_folder, claim_folder

    out = check_output_folder(out, "sweep", SWEEP_OUTPUTS)  # ~ expanded, links followed
    sweep.check()
    jobs = prepare(sweep, out)
    runs = out / "runs"
    for path in (runs, *(runs / job["id"] for job in jobs)):
        if os.path.lexists(path) and not path.is_dir():
            raise InputError(f"{path}: a file where the sweep keeps a run's folder; remove it")
    on_disk = _rows_on_disk(out) if out.exists() else {}
    if on_disk and not resume:
        raise InputError(
            f"{out}: holds a sweep already ({len(on_disk)} runs); --resume to finish it, "
            "or choose another --out"
        )
    getattr(engine, "start", lambda: None)()  # a sweep that cannot start writes nothing
    claim_folder(out, "sweep", SWEEP_OUTPUTS)
    if sweep.text:
        (out / "sweep.yaml").write_text(sweep.text)
    rows: dict[str, dict] = {}
    for job in jobs:
        row = on_disk.get(job["id"])
        if row is not None and row.get("status") in FINISHED:
            rows[job["id"]] = row
    todo = [job for job in jobs if job["id"] not in rows]
    for job in todo:  # a crashed or interrupted run starts from an empty folder
        shutil.rmtree(out / "runs" / job["id"], ignore_errors=True)
    bar = SweepProgress(len(jobs), len(rows), enabled=progress)
    skipped = len(rows)
    interrupted = False
    # The workers' scratch folders live in one the sweep owns and removes when it ends: a
    # worker that dies (a crash, a plug-in that ends its process, a kill) cannot remove
    # its own. A worker on another machine, where this path is not, uses its own.
    with tempfile.TemporaryDirectory(prefix="cake-drake-sweep-", ignore_cleanup_errors=True) as tmp:
        events = engine.events([{**job, "scratch": tmp} for job in todo])
        try:
            for event in events:
                kind, job = event[0], event[1]
                if kind == "done":
                    rows[job["id"]] = _keep(out, job, event[2])
                    bar.event(kind, job, rows[job["id"]])
                else:
                    bar.event(kind, job)
        except KeyboardInterrupt:
            interrupted = True
            events.close()
        finally:
            bar.close()
    ordered = [rows[job["id"]] for job in jobs if job["id"] in rows]
    result = SweepResult(out, ordered, len(jobs), interrupted, skipped)
    result.written = write_table(ordered, out, columns=list(jobs[0]["params"]) if jobs else [])
    series = "case" if sweep.cases else None
    result.written += write_plots(ordered, out / "plots", sweep.plot_axes, series)
    return result
