"""``python -m cake_drake.sweep SWEEP.yaml``: many runs in parallel (see ``--help``).

The argument parsing lives in :mod:`cake_drake.commands.sweep`; the library is
:mod:`cake_drake.sweeps`.
"""

import sys

from cake_drake.commands.sweep import main_sweep
from cake_drake.errors import run_cli

if __name__ == "__main__":
    sys.exit(run_cli(main_sweep))
