"""``python -m cake_drake.world``: lay out a problem's initial state and render it.

The argument parsing lives in :mod:`cake_drake.cli`; the work in :mod:`.show`.
"""

import sys

from cake_drake.cli import main_world
from cake_drake.errors import run_cli

if __name__ == "__main__":
    sys.exit(run_cli(main_world))
