"""What runs inside a worker: one scenario, built and simulated there, reduced to a row.

A job is plain data (the run's id and its scenario as YAML text) and so is what comes
back (the row and the run's output files as bytes): pydrake objects never cross a
process boundary, so the same function runs in a local process pool and on a Ray node,
and the files reach the machine that writes the table whatever machine ran the run.
"""

from __future__ import annotations

import math
import os
import socket
import tempfile
import time
from pathlib import Path

import numpy as np

#: Row fields about the run itself, in table order (parameters go between id and these).
METRICS = (
    "status",
    "success",
    "error",
    "message",
    "n_blocks",
    "plan_length",
    "planner_used",
    "plan_optimal",
    "actions_done",
    "n_actions",
    "sim_s",
    "wall_s",
    "planning_s",
    "simulation_wall_s",
    "ik_s",
    "ik_solves",
    "rtf",
    "tracking_rms_mrad",
    "tracking_max_mrad",
    "max_offset_mm",
    "collisions",
    "unmet_goals",
    "faults",
    "events",
    "replans",
    "worker",
)
#: Columns that measure the machine rather than the run (they differ between engines).
TIMINGS = ("wall_s", "planning_s", "simulation_wall_s", "ik_s", "rtf", "worker")


def empty_row(job: dict) -> dict:
    row = {name: None for name in METRICS}
    row.update(run_id=job["id"], success=False, error="", message="")
    return row


def crashed_row(job: dict, why: str) -> dict:
    """The row of a run whose worker died (a crash, or a kill) before it answered."""
    row = empty_row(job)
    row.update(status="crashed", error=why, message=why)
    return row


def execute(job: dict) -> dict:
    """Run one job: ``{"id", "scenario" (YAML text), "collect" (list), "scratch" (a folder
    for its files while it runs; optional)}`` ->
    ``{"row": dict, "files": {name: bytes}}``. Never raises for a failing run."""
    from cake_drake import pipeline  # noqa: F401 - imported before the clock starts
    from cake_drake.processes import temporaries_in

    row = empty_row(job)
    row["worker"] = f"{socket.gethostname()}:{os.getpid()}"
    t0 = time.perf_counter()
    scratch = job.get("scratch")  # the sweep's own scratch folder, where it can be seen
    scratch = scratch if scratch and os.path.isdir(scratch) else None
    # Every temporary file of the run (the cake's drawing, a planner's files) goes there
    # too: a worker killed mid-run leaves nothing the sweep does not remove.
    with temporaries_in(scratch):
        return _execute(job, row, t0, scratch)


def _execute(job: dict, row: dict, t0: float, scratch: str | None) -> dict:
    from pydrake.common.yaml import yaml_load_typed

    from cake_drake.errors import CakeDrakeError
    from cake_drake.scenario import Scenario, dump_scenario

    files: dict[str, bytes] = {}
    scenario = None
    with tempfile.TemporaryDirectory(prefix="cake-drake-run-", dir=scratch) as tmp:
        folder = Path(tmp) / "out"
        try:
            scenario = yaml_load_typed(schema=Scenario, data=job["scenario"])
            final_folder = scenario.outputs.folder
            scenario.outputs.folder = str(folder)
            row.update(_run(scenario, job.get("collect", []), folder))
            scenario.outputs.folder = final_folder
        except CakeDrakeError as e:
            row.update(status="failed", error=str(e), message=str(e))
        except Exception as e:  # noqa: BLE001 - a failing run is a row, never the sweep's end
            text = (str(e).strip().splitlines() or [""])[0]
            error = f"{type(e).__name__}: {text}" if text else type(e).__name__
            row.update(status="failed", error=error, message=error)
        row["wall_s"] = round(time.perf_counter() - t0, 4)
        if folder.is_dir():
            files = {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}
    if scenario is not None:  # the resolved scenario, naming the run's own folder
        files["scenario.yaml"] = dump_scenario(scenario).encode()
    else:
        files["scenario.yaml"] = job["scenario"].encode()
    return {"row": row, "files": files}


def _run(scenario, collect: list[str], folder: Path) -> dict:
    from cake_drake.pipeline import run
    from cake_drake.plugins import resolve
    from cake_drake.sweeps.collect import COLLECTORS
    from cake_drake.symbolic.roles import blocksworld_view

    result = run(scenario, write=True, quiet=True)
    e, plan = result.execution, result.plan
    err = e.logs.q - e.logs.q_d
    row = {
        "status": "done",
        "success": bool(result.success),
        "message": result.message,
        "n_blocks": len(blocksworld_view(result.problem).blocks),
        "plan_length": len(plan.actions),
        "planner_used": plan.planner,
        "plan_optimal": bool(plan.optimal),
        "actions_done": int(e.actions_done),
        "n_actions": int(e.n_actions),
        "sim_s": round(float(e.sim_s), 4),
        "planning_s": round(result.stages.get("planning", math.nan), 4),
        "simulation_wall_s": round(float(e.wall_s), 4),
        # IK runs inside the simulation: its share of simulation_wall_s.
        "ik_s": round(sum(result.cake.ik.times_ms) / 1000, 4) if result.cake.ik else None,
        "ik_solves": len(result.cake.ik.times_ms) if result.cake.ik else 0,
        "rtf": round(float(e.rtf), 3),
        "tracking_rms_mrad": round(float(np.sqrt(np.mean(err**2))) * 1000, 4) if err.size else None,
        "tracking_max_mrad": round(float(np.max(np.abs(err))) * 1000, 4) if err.size else None,
        "max_offset_mm": round(max(e.offsets.values(), default=0.0) * 1000, 3),
        "collisions": len(e.warnings),
        "unmet_goals": len(result.unmet),
        "faults": "; ".join(f"{type(f).__name__.lower()} {vars(f)}" for f in result.faults),
        "events": len(e.monitoring.get("events", [])),
        "replans": int(e.monitoring.get("replans", 0)),
    }
    for spec in collect:
        extra = resolve(spec, COLLECTORS, "collector")(result, folder)
        row.update(extra or {})
    return row
