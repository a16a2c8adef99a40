"""``python -m cake_drake.record SPEC --out DATASET``: demonstrations as a LeRobot dataset.

The argument parsing lives in :mod:`cake_drake.commands.record`; the library is
:mod:`cake_drake.learning.data.recording`.
"""

import sys

from cake_drake.commands.record import main_record
from cake_drake.errors import run_cli

if __name__ == "__main__":
    sys.exit(run_cli(main_record))
