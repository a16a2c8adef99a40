"""Collectors: functions a sweep runs in the worker after each run, beside the metrics.

A collector is ``collect(result: RunResult, folder: Path) -> dict | None``: the dict adds
columns to the run's row (plain numbers or text), and files it writes to ``folder`` are
kept with the run's outputs. A sweep file names collectors in ``collect:`` by a name
below or as ``module:attribute`` of your own (e.g. to keep demonstrations for a learned
layer).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np


def logs(result, folder: Path) -> dict:
    """Keep the measured logs as ``logs.npz``: t, q, v, q_d, v_d, a_d, tau_commanded,
    tau_applied, fingers_d, phase, action (what a demonstration or a gains study needs)."""
    lg = result.execution.logs
    np.savez_compressed(
        folder / "logs.npz",
        t=lg.t,
        q=lg.q,
        v=lg.v,
        q_d=lg.q_d,
        v_d=lg.v_d,
        a_d=lg.a_d,
        tau_commanded=lg.tau_commanded,
        tau_applied=lg.tau_applied,
        fingers_d=lg.fingers_d,
        phase=lg.phase,
        action=lg.action,
    )
    return {}


COLLECTORS: dict[str, Callable[..., dict | None]] = {"logs": logs}
