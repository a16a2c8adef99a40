"""``python -m cake_drake.run``: the whole cake from the command line (see ``--help``).

The argument parsing lives in :mod:`cake_drake.commands.run`; the library call is
:func:`cake_drake.pipeline.run`.
"""

from cake_drake.commands.run import main_run
from cake_drake.errors import exit_now, run_cli

if __name__ == "__main__":
    exit_now(run_cli(main_run))
