"""Recovery from random faults, with and without the execution monitor: the recovery sweep.

    python benchmarks/recovery.py [--workers N | --ray [ADDRESS]] [--out DIR]
                                  [--perception depth [--depth-noise]]

Runs ``models/sweeps/recovery.yaml`` (50 random faults, ``RandomFault`` drawn from each
run's seed, on problem_5 and on a generated six-block problem, closed loop and open
loop) on the sweep engine, then prints, per problem and loop, how often the goal was
reached, the mean extra simulated time over the fault-free run, and the mean replans.
``--perception depth`` runs the same sweep with the cake reading the cubes from the
cameras (docs/perception.md), ``--depth-noise`` with the depth noise model.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

from machine import machine  # benchmarks/machine.py

from cake_drake.pipeline import run
from cake_drake.scenario import Scenario
from cake_drake.sweeps import LocalPool, RayCluster, load_sweep, read_table, run_sweep

ROOT = Path(__file__).resolve().parent.parent

SWEEP = ROOT / "models" / "sweeps" / "recovery.yaml"


def fault_free_sim_s(case_scenario: Scenario) -> float:
    s = case_scenario
    s.faults = []
    return run(s, write=False).execution.sim_s


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--workers", type=int, default=None)
    p.add_argument("--ray", nargs="?", const="", default=None, help="local Ray, or ADDRESS")
    p.add_argument("--out", type=Path, default=None, help="keep the sweep's folder here")
    p.add_argument("--perception", default="truth", help="perception.estimator (default truth)")
    p.add_argument("--depth-noise", action="store_true", help="perception.noise.model: axial")
    args = p.parse_args()
    print(machine())
    sweep = load_sweep(SWEEP)
    sweep.base.perception.estimator = args.perception
    if args.depth_noise:
        sweep.base.perception.noise.model = "axial"
    print(f"perception: {args.perception}{', depth noise' if args.depth_noise else ''}")
    engine = RayCluster(args.ray or None) if args.ray is not None else LocalPool(args.workers)
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp) / "recovery"
        run_sweep(sweep, out, engine, progress=True)
        rows = read_table(out / "results.parquet")
    base = {}
    for r in sweep.runs():
        case = r.params.get("case")
        if case not in base:
            base[case] = fault_free_sim_s(r.scenario)
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for row in rows:
        groups[(row["case"], row["reference.action_source"])].append(row)
    print("\nproblem | loop | goal reached | rate | extra simulated s (mean, successes) | replans")
    print("--- | --- | --- | --- | --- | ---")
    for (case, source), rs in sorted(groups.items()):
        ok = [r for r in rs if r["success"]]
        extra = statistics.mean(r["sim_s"] - base[case] for r in ok) if ok else 0.0
        loop = "monitor" if source == "monitor" else "open loop"
        print(
            f"{case} | {loop} | {len(ok)}/{len(rs)} | {100 * len(ok) / len(rs):.0f} % | "
            f"{extra:.1f} | {statistics.mean(r['replans'] or 0 for r in rs):.2f}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
