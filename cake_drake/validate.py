"""``python -m cake_drake.validate``: check a plan against a problem (see ``--help``).

The argument parsing and the command live in :mod:`cake_drake.commands.validate`.
"""

import sys

from cake_drake.commands.validate import main_validate
from cake_drake.errors import run_cli

if __name__ == "__main__":
    sys.exit(run_cli(main_validate))
