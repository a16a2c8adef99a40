"""``validate``: check a plan against a PDDL problem, VAL-style."""

from __future__ import annotations

import argparse

from cake_drake.commands.common import CliParser
from cake_drake.errors import EXIT_NO_PLAN, EXIT_OK
from cake_drake.symbolic import facts_str, load_problem, read_plan, validate_plan

VALIDATE_DOC = """Validate a plan against a PDDL problem, VAL-style.

Applies the plan's actions from the initial state. Names the first step that
is not applicable with its unmet preconditions (or that is not an action of
the domain), or else the goal facts left unmet at the end. Accepts plan.txt,
pyperplan's .soln and Fast Downward's sas_plan.

exit codes: 0 valid; 1 invalid; 2 bad input (unreadable or malformed files).
"""


def validate_parser() -> argparse.ArgumentParser:
    parser = CliParser(
        prog="python -m cake_drake.validate",
        description=VALIDATE_DOC,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("domain", metavar="DOMAIN", help="PDDL domain file")
    parser.add_argument("problem", metavar="PROBLEM", help="PDDL problem file")
    parser.add_argument("plan", metavar="PLAN", help="plan file, one (action args) per line")
    parser.add_argument(
        "-v", "--verbose", action="store_true", help="print every step and the final state"
    )
    return parser


def main_validate(argv: list[str] | None = None) -> int:
    args = validate_parser().parse_args(argv)
    problem = load_problem(args.domain, args.problem)
    actions = read_plan(args.plan)
    result = validate_plan(problem, actions)
    if args.verbose:
        for i, action in enumerate(actions, start=1):
            if result.failed_step is not None and i >= result.failed_step:
                print(f"{i:3d}  {action}  FAILS")
                break
            print(f"{i:3d}  {action}  ok")
        print(f"final state: {facts_str(result.final_state)}")
    if result.ok:
        print(f"plan {args.plan} is {result.message}")
        return EXIT_OK
    print(f"plan {args.plan} is invalid: {result.message}")
    return EXIT_NO_PLAN
