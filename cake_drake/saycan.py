"""``python -m cake_drake.saycan``: map a SayCan transcript onto a kitchen (see ``--help``).

The argument parsing and the command live in :mod:`cake_drake.commands.saycan`.
"""

import sys

from cake_drake.commands.saycan import main_saycan
from cake_drake.errors import run_cli

if __name__ == "__main__":
    sys.exit(run_cli(main_saycan))
