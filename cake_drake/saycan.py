"""Map a SayCan-style transcript onto a PDDL kitchen domain and show where STRIPS breaks.

Reads the robot's numbered steps, maps each through a small lexicon (skill
phrases -> action schemas, noun phrases -> problem objects), simulates them
against the problem and prints a per-step verdict: maps cleanly; maps to
several actions (an implicit decomposition, what an HTN method would express);
precondition fails (with the unmet facts); no schema (verb or object not in
the domain, with the vocabulary). Then checks the goal, plans the same problem
and shows both plans side by side. Writes plan.txt (the transcribed PDDL plan),
problem.pddl and report.md to --out.

Without --problem the default kitchen is used: it has no goal, so only the
steps' executability is checked and the state reached is reported.

exit codes: 0 the transcribed plan is valid and reaches the goal (or, without
a goal, every step executes); 1 it maps but fails; 2 unreadable input.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cake_drake.errors import EXIT_NO_PLAN, EXIT_OK, CliParser, run_cli
from cake_drake.language import (
    KITCHEN_DEFAULT,
    KITCHEN_DOMAIN,
    analyse,
    load_transcript,
    render_text,
    write_outputs,
)
from cake_drake.symbolic import DEFAULT_PLANNER, load_problem, planner_info


def build_parser() -> argparse.ArgumentParser:
    parser = CliParser(
        prog="python -m cake_drake.saycan",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("transcript", metavar="TRANSCRIPT", help="transcript text file")
    parser.add_argument(
        "--domain", default=str(KITCHEN_DOMAIN), help="PDDL domain (default: kitchen.pddl)"
    )
    parser.add_argument(
        "--problem",
        default=str(KITCHEN_DEFAULT),
        help="PDDL problem (default: kitchen_default.pddl, which has no goal)",
    )
    parser.add_argument(
        "--out", type=Path, help="output folder (default: outputs/saycan/<transcript name>)"
    )
    parser.add_argument(
        "--planner", default=DEFAULT_PLANNER, help=f"planner for the comparison ({DEFAULT_PLANNER})"
    )
    parser.add_argument(
        "--time-limit", type=float, default=30.0, metavar="S", help="planner time limit (30 s)"
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    planner_info(args.planner)
    transcript = load_transcript(args.transcript)
    problem = load_problem(args.domain, args.problem, require_goal=False)
    analysis = analyse(transcript, problem, args.planner, args.time_limit)
    print(render_text(analysis), end="")
    out = args.out or Path("outputs") / "saycan" / Path(args.transcript).stem
    write_outputs(analysis, out)
    print(f"wrote {out}/plan.txt, problem.pddl, report.md")
    return EXIT_OK if analysis.ok else EXIT_NO_PLAN


if __name__ == "__main__":
    sys.exit(run_cli(main))
