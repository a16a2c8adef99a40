"""Fast Downward as a subprocess, from the ``up-fast-downward`` wheel (the ``fd`` extra).

The wheel ships the ``fast-downward.py`` driver and a compiled ``downward``
binary; we call the driver directly (no unified-planning needed at run time)
with a wall-clock timeout, since Fast Downward's own limits count CPU time. Its
processes are a group this process owns (:mod:`cake_drake.processes`): none of them
outlives the run, whatever ends it.
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from cake_drake import processes
from cake_drake.errors import CakeDrakeError, InputError
from cake_drake.symbolic.pddl import GroundAction, Problem
from cake_drake.symbolic.plans import parse_plan_text

INSTALL_HINT = "pip install -e '.[fd]'"

# Exit codes of the Fast Downward driver (driver/returncodes.py).
_UNSOLVABLE = {10, 11}  # translator or search proved the task unsolvable
_INCOMPLETE = {12}  # an incomplete search ran out of states without a plan
_OUT_OF_TIME = {21, 23, 24}
_OUT_OF_MEMORY = {20, 22}


def driver_path() -> Path | None:
    """The ``fast-downward.py`` driver of the installed wheel, or None."""
    spec = importlib.util.find_spec("up_fast_downward")
    if spec is None or not spec.submodule_search_locations:
        return None
    for location in spec.submodule_search_locations:
        p = Path(location) / "downward" / "fast-downward.py"
        if p.is_file():
            return p
    return None


def available() -> bool:
    return driver_path() is not None


class FdResult:
    """What a Fast Downward run returned: ``status`` is ``"plan"``, ``"unsolvable"``,
    ``"incomplete"``, ``"limit"`` (time) or ``"memory"``."""

    def __init__(self, status: str, actions: tuple[GroundAction, ...] = (), time_s: float = 0.0):
        self.status = status
        self.actions = actions
        self.time_s = time_s


def run(problem: Problem, alias: str, planner: str, time_limit: float | None) -> FdResult:
    """Run Fast Downward with ``--alias alias`` on ``problem``."""
    driver = driver_path()
    if driver is None:
        raise InputError(
            f"planner {planner} needs Fast Downward, which is not installed: "
            f"run {INSTALL_HINT} (the up-fast-downward wheel), or choose a pyperplan planner"
        )
    with tempfile.TemporaryDirectory(prefix="cake_drake_fd_") as tmp:
        dom = Path(tmp) / "domain.pddl"
        prob = Path(tmp) / "problem.pddl"
        dom.write_text(problem.domain.text, encoding="utf-8")
        prob.write_text(problem.text, encoding="utf-8")
        cmd = [sys.executable, str(driver), "--plan-file", "sas_plan", "--alias", alias]
        cmd += [str(dom), str(prob)]
        t0 = time.perf_counter()
        # A group of its own (driver, translate, search) that ends with this run however
        # it ends: the limit, an interrupt, an exception, even this process killed.
        with processes.owned(
            cmd, cwd=tmp, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        ) as proc:
            try:
                out, _ = proc.communicate(timeout=time_limit)
            except subprocess.TimeoutExpired:
                processes.stop(proc)
                return FdResult("limit", time_s=time.perf_counter() - t0)
            elapsed = time.perf_counter() - t0
        plan_file = Path(tmp) / "sas_plan"
        if proc.returncode == 0 and plan_file.is_file():
            text = plan_file.read_text(encoding="utf-8")
            return FdResult("plan", parse_plan_text(text, "sas_plan"), elapsed)
        if proc.returncode in _UNSOLVABLE:
            return FdResult("unsolvable", time_s=elapsed)
        if proc.returncode in _INCOMPLETE:
            return FdResult("incomplete", time_s=elapsed)
        if proc.returncode in _OUT_OF_TIME:
            return FdResult("limit", time_s=elapsed)
        if proc.returncode in _OUT_OF_MEMORY:
            return FdResult("memory", time_s=elapsed)
        last = next((ln for ln in reversed(out.splitlines()) if ln.strip()), "no output")
        raise CakeDrakeError(
            f"Fast Downward ({alias}) failed with exit code {proc.returncode}: {last.strip()}"
        )
