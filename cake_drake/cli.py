"""``cake-drake COMMAND ...``: the table of commands and the console script.

Each command is a module of :mod:`cake_drake.commands` holding its doc, its parser and
its main (``python -m cake_drake.COMMAND`` runs the same main); the exit codes every
command shares are in :mod:`cake_drake.commands`. The library never imports this module.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

from cake_drake.commands.evaluate import main_evaluate
from cake_drake.commands.gains import main_gains
from cake_drake.commands.plan import main_plan
from cake_drake.commands.record import main_record
from cake_drake.commands.run import main_run
from cake_drake.commands.saycan import main_saycan
from cake_drake.commands.sweep import main_sweep
from cake_drake.commands.train import main_train
from cake_drake.commands.validate import main_validate
from cake_drake.commands.world import main_world
from cake_drake.errors import EXIT_OK, run_cli

COMMANDS: dict[str, tuple[Callable[[list[str] | None], int], str]] = {
    "run": (main_run, "plan and execute a problem on the simulated Panda (a scenario)"),
    "gains": (main_gains, "the Kd study: replay one reference per Kd"),
    "sweep": (main_sweep, "many runs in parallel (local pool or Ray): a table and plots"),
    "world": (main_world, "lay out a problem's initial state and render it"),
    "plan": (main_plan, "plan only"),
    "validate": (main_validate, "check a plan against a problem, VAL-style"),
    "saycan": (main_saycan, "map a SayCan-style transcript onto the kitchen domain"),
    "record": (main_record, "demonstrations as a LeRobot dataset; replay one"),
    "evaluate": (main_evaluate, "a policy's success rate on seeded problems"),
    "train": (main_train, "train a policy on a recording with LeRobot's own loop"),
}


def main(argv: list[str] | None = None) -> int:
    """``cake-drake COMMAND [ARGS]``: the console script."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] in ("-h", "--help"):
        print("usage: cake-drake COMMAND [ARGS ...]\n\ncommands:")
        for name, (_, summary) in COMMANDS.items():
            print(f"  {name:<9} {summary}")
        print("\n`cake-drake COMMAND --help` describes one.")
        return EXIT_OK if argv else 2
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(
            f"error: cake-drake: unknown command {name!r}; choose one of: " + ", ".join(COMMANDS),
            file=sys.stderr,
        )
        return 2
    return run_cli(COMMANDS[name][0], rest)


def console() -> None:
    sys.exit(main())


if __name__ == "__main__":
    console()
