"""One exception hierarchy for the whole project.

Every message names the input, the place (``file:line[:col]`` where there is one)
and what would be valid. The command-line tools turn these into one line on
stderr and the exit code stored on the class.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable

#: Documented exit codes of every command-line tool.
EXIT_OK = 0
EXIT_NO_PLAN = 1  # no plan (proved or limit reached); an invalid plan; a plan that fails
EXIT_BAD_INPUT = 2  # unreadable or malformed input, bad options
EXIT_EXECUTION_FAILED = 3  # the plan could not be executed in the simulated world


class CakeDrakeError(Exception):
    """Base class: a problem the user can act on, with a one-line message."""

    exit_code = EXIT_BAD_INPUT


class InputError(CakeDrakeError):
    """A file or option that cannot be used as given (missing, unreadable, malformed)."""

    exit_code = EXIT_BAD_INPUT


class PddlError(InputError):
    """PDDL text that does not parse or does not fit its domain."""


class NoPlanError(CakeDrakeError):
    """The planner found no plan: proved unsolvable, or it gave up at a limit."""

    exit_code = EXIT_NO_PLAN


class ExecutionError(CakeDrakeError):
    """The plan could not be carried out by the robot (IK failure, goal not reached)."""

    exit_code = EXIT_EXECUTION_FAILED


class IkError(ExecutionError):
    """Inverse kinematics found no joint configuration for a named waypoint."""


def run_cli(main: Callable[[list[str] | None], int], argv: list[str] | None = None) -> int:
    """Call ``main`` and turn a :class:`CakeDrakeError` into one line and its exit code."""
    try:
        return main(argv)
    except CakeDrakeError as e:
        print(f"error: {e}", file=sys.stderr)
        return e.exit_code
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader went away (e.g. `| head`): stop quietly, as Unix tools do.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_OK
