"""``python -m cake_drake.gains``: the Kd study (see ``--help``).

The entry point only: the study is the library (:mod:`cake_drake.gains`), the argument
parsing and the command live in :mod:`cake_drake.commands.gains`.
"""

import sys

from cake_drake.commands.gains import main_gains
from cake_drake.errors import run_cli

if __name__ == "__main__":
    sys.exit(run_cli(main_gains))
