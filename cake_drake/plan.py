"""Plan a PDDL problem and print the plan (defaults: Blocksworld, problem_5).

Prints one action per line, then a one-line note: planner, search,
heuristic, length (optimal or satisficing) and time. The default planner,
auto, runs A* with LM-cut (optimal) within a budget of about three seconds,
then weighted A* and greedy best-first with hFF (satisficing); the note says
which one produced the plan and whether it is proved optimal.

The optimal plan for problem_5 has 10 actions. A satisficing planner returns
whatever plan it finds first, which may be longer: gbfs-ff returns 14, and the
"12" quoted by the exercise can only come from such a search.

exit codes: 0 plan found; 1 no plan (proved unsolvable, or the time limit
was reached -- the message says which); 2 bad input (files, options).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cake_drake.errors import EXIT_OK, CliParser, InputError, run_cli
from cake_drake.symbolic import (
    BLOCKSWORLD_DOMAIN,
    DEFAULT_PLANNER,
    PLANNERS,
    PROBLEM_5,
    PROBLEM_5_OPTIMAL_LENGTH,
    load_problem,
    planner_info,
    solve_problem,
    write_plan,
)


def build_parser() -> argparse.ArgumentParser:
    planners = "\n".join(f"  {p.name:<18} {p.summary}" for p in PLANNERS.values())
    parser = CliParser(
        prog="python -m cake_drake.plan",
        description=__doc__,
        epilog=f"planners:\n{planners}",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "files",
        nargs="*",
        metavar="DOMAIN PROBLEM",
        help=f"PDDL domain and problem (default: {BLOCKSWORLD_DOMAIN.name} {PROBLEM_5.name})",
    )
    parser.add_argument(
        "--planner", default=DEFAULT_PLANNER, help=f"planner name (default: {DEFAULT_PLANNER})"
    )
    parser.add_argument("-o", "--output", metavar="PLAN", help="also write the plan to this file")
    parser.add_argument(
        "--time-limit", type=float, metavar="S", help="give up after S seconds (wall clock)"
    )
    return parser


#: The planner the notes recommend for a proof of optimality.
OPTIMAL_PLANNER = "astar-lmcut"


def _is_problem_5(path: Path) -> bool:
    try:
        return path.resolve().samefile(PROBLEM_5)
    except OSError:
        return False


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if len(args.files) not in (0, 2):
        raise InputError(
            f"expected DOMAIN and PROBLEM (or neither for the defaults), got {len(args.files)} "
            f"file{'s' * (len(args.files) != 1)}: {' '.join(args.files)}"
        )
    domain, problem_path = (
        (Path(args.files[0]), Path(args.files[1]))
        if args.files
        else (BLOCKSWORLD_DOMAIN, PROBLEM_5)
    )
    info = planner_info(args.planner)
    problem = load_problem(domain, problem_path)
    plan = solve_problem(problem, info.name, args.time_limit)

    for action in plan.actions:
        print(action)
    print(plan.note())
    if _is_problem_5(problem_path):
        if plan.optimal:
            print(
                f"note: {plan.length} actions is the optimum for problem_5; the exercise's "
                "'12' (and gbfs-ff's 14) is what a satisficing planner returns"
            )
        else:
            print(
                f"note: the optimal plan for problem_5 has {PROBLEM_5_OPTIMAL_LENGTH} actions; "
                f"{info.name} is satisficing (returns the first plan it finds), which is how "
                "the exercise's '12' and gbfs-ff's 14 arise"
            )
    elif not plan.optimal:
        print(
            f"note: {plan.planner} is satisficing (a shorter plan may exist); "
            f"--planner {OPTIMAL_PLANNER} finds the shortest, without a budget"
        )
    if args.output:
        write_plan(plan, args.output)
        print(f"plan written to {args.output}")
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(run_cli(main))
