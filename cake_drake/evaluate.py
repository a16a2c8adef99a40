"""``python -m cake_drake.evaluate POLICY --suite SPEC``: a policy's success rate, measured.

The argument parsing lives in :mod:`cake_drake.commands.evaluate`; the library is
:mod:`cake_drake.learning.data.recording`.
"""

import sys

from cake_drake.commands.evaluate import main_evaluate
from cake_drake.errors import run_cli

if __name__ == "__main__":
    sys.exit(run_cli(main_evaluate))
