"""``python -m cake_drake.world``: lay out a problem's initial state and render it.

The argument parsing and the layout live in :mod:`cake_drake.commands.world`; the
pictures in :mod:`.render`.
"""

from cake_drake.commands.world import main_world
from cake_drake.errors import exit_now, run_cli

if __name__ == "__main__":
    exit_now(run_cli(main_world))
