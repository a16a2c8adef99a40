"""``saycan``: map a SayCan transcript onto a PDDL kitchen and show where STRIPS breaks.

The mapping is the library's (:mod:`cake_drake.language`); this module parses its flags.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cake_drake.commands.common import CliParser, check_time_limit
from cake_drake.errors import EXIT_NO_PLAN, EXIT_OK
from cake_drake.symbolic import DEFAULT_PLANNER, load_problem, planner_info

SAYCAN_DOC = """Map a SayCan transcript onto a PDDL kitchen domain and show where STRIPS breaks.

Reads the robot's numbered steps and maps each through a small lexicon: a skill
phrase stands for HTN-style methods, and the first whose precondition holds in
the current state decides the ground actions ("put down X" where an open
container stands is put-in). Simulates the steps against the problem and prints
a per-step verdict: maps cleanly; maps via a method (which fired, and why);
maps to several actions; precondition fails (with the unmet facts); ambiguous
(a noun naming several objects, with the candidates); no schema (verb or object
not in the domain, with the vocabulary). Then checks the goal, plans the same
problem, shows both plans side by side and ends with a note: what mapped, what
did not and why, what would have been needed. Writes plan.txt (the transcribed
PDDL plan), problem.pddl and report.md to --out.

Without --problem SayCan's own kitchen is used (its 15 objects, close and far
counter, table, trash can, bowl, the user). It has no goal: the transcript's
"Goal:" line, if any, supplies one; otherwise only executability is checked.

exit codes: 0 the transcribed plan is valid and reaches the goal (or, without
a goal, every step executes); 1 it maps but fails (no schema, ambiguous, a
precondition fails, or the goal is not reached); 2 unreadable input.
"""


def saycan_parser() -> argparse.ArgumentParser:
    from cake_drake.language import KITCHEN_DEFAULT, KITCHEN_DOMAIN

    parser = CliParser(
        prog="python -m cake_drake.saycan",
        description=SAYCAN_DOC,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("transcript", metavar="TRANSCRIPT", help="transcript text file")
    parser.add_argument(
        "--domain", default=str(KITCHEN_DOMAIN), help="PDDL domain (default: kitchen.pddl)"
    )
    parser.add_argument(
        "--problem",
        default=str(KITCHEN_DEFAULT),
        help="PDDL problem (default: kitchen_default.pddl, SayCan's kitchen, no goal)",
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
    parser.add_argument(
        "--add-objects",
        action="store_true",
        help="declare the objects the transcript names that the problem lacks (typed from "
        "the skill that names them; where they are stays unknown) and say which",
    )
    return parser


def main_saycan(argv: list[str] | None = None) -> int:
    from cake_drake.language import (
        SAYCAN_OUTPUTS,
        analyse,
        load_transcript,
        missing_objects,
        render_text,
        with_objects,
        write_outputs,
    )
    from cake_drake.outputs.files import check_output_folder

    args = saycan_parser().parse_args(argv)
    planner_info(args.planner)
    time_limit = check_time_limit(args.time_limit)
    out = args.out or Path("outputs") / "saycan" / Path(args.transcript).stem
    inputs = (args.transcript, args.domain, args.problem)
    check_output_folder(out, "saycan", SAYCAN_OUTPUTS, inputs)
    transcript = load_transcript(args.transcript)
    problem = load_problem(args.domain, args.problem, require_goal=False)
    if args.add_objects:
        added = missing_objects(transcript, problem)
        problem = with_objects(problem, added)
        listed = ", ".join(f"{name} ({kind})" for name, kind in added) or "none"
        print(f"added objects: {listed}", file=sys.stderr)
    analysis = analyse(transcript, problem, args.planner, time_limit)
    print(render_text(analysis), end="")
    write_outputs(analysis, out, inputs)
    print(f"wrote {out}/plan.txt, problem.pddl, report.md")
    return EXIT_OK if analysis.ok else EXIT_NO_PLAN
