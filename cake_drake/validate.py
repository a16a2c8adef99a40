"""Validate a plan against a PDDL problem, VAL-style.

Applies the plan's actions from the initial state. Names the first step that
is not applicable with its unmet preconditions (or that is not an action of
the domain), or else the goal facts left unmet at the end. Accepts plan.txt,
pyperplan's .soln and Fast Downward's sas_plan.

exit codes: 0 valid; 1 invalid; 2 bad input (unreadable or malformed files).
"""

import sys

from cake_drake.cli import main_validate
from cake_drake.errors import run_cli

if __name__ == "__main__":
    sys.exit(run_cli(main_validate))
