"""``python -m cake_drake.plan``: plan a PDDL problem and print the plan (see ``--help``).

The argument parsing and the command live in :mod:`cake_drake.commands.plan`.
"""

import sys

from cake_drake.commands.plan import main_plan
from cake_drake.errors import run_cli

if __name__ == "__main__":
    sys.exit(run_cli(main_plan))
