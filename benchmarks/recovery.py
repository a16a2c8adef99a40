"""Recovery from random faults, with and without the execution monitor.

    python benchmarks/recovery.py [--faults 50] [--problems problem_5 random6]

Each fault is ``random:SEED`` (a slip, a knock or a moved cube, drawn from the seed) on
a problem; every fault runs twice, closed loop (the monitor, the default) and open loop
(``--no-monitor``). Prints one row per run and, per problem and loop, the success rate,
the mean extra simulated time over the fault-free run and the mean number of replans.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

from machine import machine  # benchmarks/machine.py

from cake_drake.pipeline import run
from cake_drake.scenario import RandomFault, Scenario
from cake_drake.symbolic import PROBLEM_5, random_problem


def problems(names: list[str], folder: Path) -> dict[str, Path]:
    out = {}
    for name in names:
        if name == "problem_5":
            out[name] = PROBLEM_5
        elif name.startswith("random"):
            n = int(name.removeprefix("random"))
            p = folder / f"{name}.pddl"
            p.write_text(random_problem(n, seed=1))
            out[name] = p
        else:
            sys.exit(f"unknown problem {name!r}: problem_5 or randomN")
    return out


def one(problem: Path, seed: int | None, monitor: bool) -> dict:
    s = Scenario()
    s.task.problem = str(problem)
    s.reference.action_source = "monitor" if monitor else "plan"
    if seed is not None:
        s.faults = [RandomFault(seed)]
    t0 = time.perf_counter()
    r = run(s, write=False)
    fault = r.faults[0] if r.faults else None
    return {
        "fault": f"{type(fault).__name__.lower()} {vars(fault)}" if fault else "-",
        "success": r.success,
        "sim_s": r.execution.sim_s,
        "wall_s": time.perf_counter() - t0,
        "replans": r.execution.monitoring.get("replans", 0),
        "events": len(r.execution.monitoring.get("events", [])),
        "message": r.message,
    }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--faults", type=int, default=50, help="random faults per problem")
    p.add_argument("--problems", nargs="+", default=["problem_5", "random6"])
    args = p.parse_args()
    print(machine())
    summary = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, path in problems(args.problems, Path(tmp)).items():
            base = one(path, None, True)
            print(f"{name}: fault-free {base['sim_s']:.1f} s simulated, success {base['success']}")
            for monitor in (True, False):
                rows = [one(path, seed, monitor) for seed in range(args.faults)]
                loop = "monitor" if monitor else "open loop"
                for seed, r in enumerate(rows):
                    print(
                        f"  {name} {loop:9} seed {seed:3d} {r['fault'][:60]:60} "
                        f"{'ok ' if r['success'] else 'FAIL'} replans {r['replans']} "
                        f"{r['sim_s']:6.1f} s  {'' if r['success'] else r['message'][:70]}",
                        flush=True,
                    )
                ok = [r for r in rows if r["success"]]
                summary.append(
                    (
                        name,
                        loop,
                        len(ok),
                        len(rows),
                        statistics.mean(r["sim_s"] - base["sim_s"] for r in ok) if ok else 0.0,
                        statistics.mean(r["replans"] for r in rows),
                    )
                )
    print()
    print("problem | loop | goal reached | rate | extra simulated s (mean, successes) | replans")
    print("--- | --- | --- | --- | --- | ---")
    for name, loop, ok, n, extra, replans in summary:
        print(f"{name} | {loop} | {ok}/{n} | {100 * ok / n:.0f} % | {extra:.1f} | {replans:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
