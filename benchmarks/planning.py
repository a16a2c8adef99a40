"""Planning benchmark: plan length and time per planner on seeded random Blocksworld problems.

Prints a Markdown table: one row per problem (problem_5, then n random blocks),
one column per planner, each cell "length / time". A planner that reaches the
per-cell time limit shows "limit"; larger sizes are then skipped ("-").
Fast Downward columns appear when the fd extra is installed. Times are the
planner's own wall-clock time (median of repeats for fast cells); for Fast
Downward they include starting its processes (~0.1 s).

    python benchmarks/planning.py            # full table (a few minutes)
    python benchmarks/planning.py --quick    # small sizes, short limit
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
from importlib.metadata import version

from cake_drake.errors import CakeDrakeError, NoPlanError
from cake_drake.symbolic import (
    BLOCKSWORLD_DOMAIN,
    PLANNERS,
    PROBLEM_5,
    fast_downward,
    load_domain,
    load_problem,
    parse_problem,
    random_problem,
    solve_problem,
)

SIZES = (5, 8, 10, 15, 20, 30)
QUICK_SIZES = (5, 8, 10)


def cpu_model() -> str:
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, timeout=5).stdout
        for line in out.splitlines():
            if line.startswith("Model name:"):
                return line.split(":", 1)[1].strip()
    except (OSError, subprocess.SubprocessError):
        pass
    return platform.processor() or "unknown CPU"


def nproc() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()


def run_cell(problem, planner: str, time_limit: float, repeats: int) -> tuple[str, bool]:
    """Returns (cell text, gave_up)."""
    times = []
    plan = None
    for _ in range(repeats):
        try:
            plan = solve_problem(problem, planner, time_limit)
        except NoPlanError as e:
            if "time limit" in str(e) or "memory" in str(e):
                return "limit", True
            return "no plan", False
        times.append(plan.time_s)
        if plan.time_s > 0.2:
            break  # slow cells are measured once
    t = statistics.median(times)
    shown = f"{t * 1000:.0f} ms" if t < 1 else f"{t:.1f} s"
    return f"{plan.length} / {shown}", False


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help=f"sizes {QUICK_SIZES}, 3 s limit")
    parser.add_argument("--time-limit", type=float, help="per-cell limit in s (default 30)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random problems")
    parser.add_argument("--planners", help="comma-separated planner names (default: all)")
    args = parser.parse_args(argv)

    sizes = QUICK_SIZES if args.quick else SIZES
    limit = args.time_limit or (3.0 if args.quick else 30.0)
    planners = args.planners.split(",") if args.planners else list(PLANNERS)
    fd = fast_downward.available()
    if not fd:
        planners = [p for p in planners if PLANNERS[p].backend != "fast-downward"]

    print(
        f"machine: {cpu_model()}, {nproc()} cores; Python {platform.python_version()}, "
        f"pyperplan {version('pyperplan')}"
        + ("" if fd else "; Fast Downward not installed (pip install -e '.[fd]')")
    )
    print(f"per-cell time limit {limit:g} s; random problems seeded with {args.seed}")
    print("cells: plan length / planner time; '*' marks optimal planners\n")

    header = ["problem"] + [p + ("*" if PLANNERS[p].optimal else "") for p in planners]
    print("| " + " | ".join(header) + " |")
    print("|" + "|".join("---" for _ in header) + "|")
    domain = load_domain(BLOCKSWORLD_DOMAIN)
    rows = [("problem_5", load_problem(BLOCKSWORLD_DOMAIN, PROBLEM_5))]
    rows += [
        (f"{n} blocks", parse_problem(domain, random_problem(n, args.seed), f"random-{n}"))
        for n in sizes
    ]
    stopped: set[str] = set()
    for label, problem in rows:
        cells = [label]
        for planner in planners:
            if planner in stopped:
                cells.append("-")
                continue
            try:
                text, gave_up = run_cell(problem, planner, limit, repeats=5)
            except CakeDrakeError as e:
                text, gave_up = f"error: {e}", True
            if gave_up:
                stopped.add(planner)
            cells.append(text)
        print("| " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
