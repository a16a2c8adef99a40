"""``python -m cake_drake.train DATASET --out DIR``: a policy trained with LeRobot's own loop.

The argument parsing lives in :mod:`cake_drake.commands.train`; the library is
:mod:`cake_drake.learning.training.train`.
"""

import sys

from cake_drake.commands.train import main_train
from cake_drake.errors import run_cli

if __name__ == "__main__":
    sys.exit(run_cli(main_train))
