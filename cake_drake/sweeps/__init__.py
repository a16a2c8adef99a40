"""Sweeps: many runs of the pipeline, in parallel on one machine or a Ray cluster.

A sweep is a base scenario plus axes over its fields and a number of seeds
(:mod:`~cake_drake.sweeps.spec`); each run is one scenario, built and simulated inside
its worker (:mod:`~cake_drake.sweeps.worker`), on a local process pool or on Ray
(:mod:`~cake_drake.sweeps.engines`); the rows go into one table with plots chosen by the
axes (:mod:`~cake_drake.sweeps.table`). :mod:`~cake_drake.sweeps.driver` runs one from
end to end; :mod:`~cake_drake.sweeps.collect` holds what a run gathers beside its
metrics, :mod:`~cake_drake.sweeps.pool` the local pool's processes. ``python -m
cake_drake.sweep SWEEP.yaml`` is the command; :func:`run_sweep` the library call.
"""

from cake_drake.sweeps.driver import SweepResult, run_sweep
from cake_drake.sweeps.engines import LocalPool, RayCluster
from cake_drake.sweeps.pool import spawn_imap
from cake_drake.sweeps.spec import Sweep, load_sweep, parse_sweep
from cake_drake.sweeps.table import read_table

__all__ = [
    "LocalPool",
    "RayCluster",
    "Sweep",
    "SweepResult",
    "load_sweep",
    "parse_sweep",
    "read_table",
    "run_sweep",
    "spawn_imap",
]
