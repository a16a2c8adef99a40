"""The learned planner against the classical ones, on the same held-out problems.

For each size (3, 6, 9, 12, 20, 30 and 50 blocks) it generates problems on seeds
the training never used (100000 and up), cycling through the project's naming
(complete goals) and the IPC and typed variants (tall towers, partial goals),
as ``suite_problems`` does. Every planner plans every problem within a time
limit; every plan is validated (the registry does it). Prints one Markdown
table, with the machine:

- solved: the share of problems planned within the limit;
- length / optimal: the mean ratio of plan length to the optimal length, where
  the optimal length is known (exact breadth-first search up to 7 blocks,
  A* with LM-cut where it finishes within --astar-limit, 10 s);
- length / best: the mean ratio to the shortest plan any planner found for that
  problem (over the problems the planner solved);
- time: the median and the largest planning time per problem, on one core.

    python benchmarks/learned_planner.py                       # 100 problems a size
    python benchmarks/learned_planner.py --problems 10 --sizes 3 6 12   # quick
    python benchmarks/learned_planner.py --planners learned learned@models/planners/blocks_reward \
        --figure docs/images/planner_reward.png    # imitation against reward, drawn
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

from machine import machine

from cake_drake.errors import CakeDrakeError
from cake_drake.symbolic import (
    NAMINGS,
    load_domain,
    parse_problem,
    random_problem,
    solve_problem,
)
from cake_drake.symbolic.learned import read_problem

SIZES = (3, 6, 9, 12, 20, 30, 50)
PLANNERS = ("learned", "astar-lmcut", "wastar-ff", "gbfs-ff", "fd-lama-first")
#: A* with LM-cut is tried only up to this size (it takes minutes at 10-12 blocks).
OPTIMAL_UP_TO = 9
EXACT_UP_TO = 7
FIRST_SEED = 100000


def problems(n: int, count: int):
    """``count`` held-out problems of ``n`` blocks: (name, Problem), in three namings."""
    out = []
    for seed in range(FIRST_SEED, FIRST_SEED + count):
        kind = seed % 3
        style = NAMINGS[("exercise", "ipc", "typed")[kind]]
        text = random_problem(n, seed, style, tall=kind == 1, max_height=10,
                              goal_max_height=9, partial=kind > 0)  # fmt: skip
        out.append(
            (f"{style.name}-{n}-{seed}", parse_problem(load_domain(style.domain_file), text))
        )
    return out


def exact_length(problem) -> int:
    """The optimal plan length by breadth-first search over every state (small problems)."""
    from cake_drake.learning.training.planner import Space

    _, graph = read_problem(problem)
    space = Space(len(graph.below))
    return int(space.distances(graph)[space.index[graph.below]])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    ap.add_argument("--problems", type=int, default=100, help="problems per size")
    ap.add_argument("--planners", nargs="+", default=list(PLANNERS))
    ap.add_argument("--time-limit", type=float, default=30.0, help="s per plan")
    ap.add_argument("--astar-limit", type=float, default=10.0, help="s per A* plan")
    ap.add_argument("--learned", default="learned", help="learned or learned@DIR")
    ap.add_argument("--figure", help="PNG: each planner's share solved and length / best by size")
    args = ap.parse_args(argv)
    drawn: dict[str, list[tuple[int, float, float]]] = {}
    planners = [args.learned if p == "learned" else p for p in args.planners]
    print(machine())
    print(f"{args.problems} problems a size (seeds {FIRST_SEED}+), {args.time_limit:g} s a plan\n")
    print(
        "| blocks | planner | solved | length / optimal | length / best | time median | time max |"
    )
    print("|---|---|---|---|---|---|---|")
    for n in args.sizes:
        cases = problems(n, args.problems)
        found: dict[str, dict[str, tuple[int, float]]] = {p: {} for p in planners}
        optimal: dict[str, int] = {}
        for name, problem in cases:
            if n <= EXACT_UP_TO:
                optimal[name] = exact_length(problem)
            for p in planners:
                if p == "astar-lmcut" and n > OPTIMAL_UP_TO:
                    continue
                limit = args.astar_limit if p == "astar-lmcut" else args.time_limit
                t0 = time.perf_counter()
                try:
                    plan = solve_problem(problem, p, limit)
                except CakeDrakeError:
                    continue
                found[p][name] = (plan.length, time.perf_counter() - t0)
                if p == "astar-lmcut":
                    optimal.setdefault(name, plan.length)
        best = {
            name: min(found[p][name][0] for p in planners if name in found[p])
            for name, _ in cases
            if any(name in found[p] for p in planners)
        }
        for p in planners:
            if p == "astar-lmcut" and n > OPTIMAL_UP_TO:
                continue
            got = found[p]
            solved = f"{100 * len(got) / len(cases):.0f} %"
            ratio_opt = [got[k][0] / optimal[k] for k in got if optimal.get(k)]
            ratio_best = [got[k][0] / best[k] for k in got if best.get(k)]
            times = [t for _, t in got.values()]

            def mean(xs):
                return f"{statistics.fmean(xs):.3f}" if xs else "-"

            t_med = f"{statistics.median(times):.3f} s" if times else "-"
            t_max = f"{max(times):.3f} s" if times else "-"
            print(f"| {n} | {p} | {solved} | {mean(ratio_opt)} | {mean(ratio_best)} | "
                  f"{t_med} | {t_max} |", flush=True)  # fmt: skip
            share = len(got) / len(cases)
            drawn.setdefault(p, []).append(
                (n, share, statistics.fmean(ratio_best) if ratio_best else float("nan"))
            )
    if args.figure:
        figure(drawn, args.figure)
    return 0


def figure(drawn: dict[str, list[tuple[int, float, float]]], path: str) -> None:
    """Two panels against the number of blocks: the share solved and length / best."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    for p, rows in drawn.items():
        n, share, ratio = zip(*rows, strict=True)
        label = {"learned": "imitation (planners/blocks)"}.get(p, p.replace("learned@models/", ""))
        if label.endswith("blocks_reward"):
            label = "reward alone (planners/blocks_reward)"
        a.plot(n, [100 * x for x in share], "o-", label=label)
        b.plot(n, ratio, "o-", label=label)
    a.set(xlabel="blocks", ylabel="problems solved (%)", ylim=(0, 105), xscale="log",
          title="solved, held-out problems")  # fmt: skip
    b.set(xlabel="blocks", ylabel="plan length / shortest found", xscale="log",
          title="plan length")  # fmt: skip
    for ax in (a, b):
        ax.set_xticks(sorted({n for rows in drawn.values() for n, _, _ in rows}))
        ax.get_xaxis().set_major_formatter(matplotlib.ticker.ScalarFormatter())
        ax.get_xaxis().set_minor_locator(matplotlib.ticker.NullLocator())
        ax.grid(alpha=0.3)
    a.legend(loc="lower left")  # one legend: the right panel's lines cross where it would be
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
