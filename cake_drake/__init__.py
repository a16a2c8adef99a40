"""cake_drake: the classical robot-manipulation cake as one Drake systems diagram.

Layers (one sub-package each): ``symbolic`` (PDDL -> plan), ``world`` (the scene),
``geometric`` (waypoints -> IK -> joint trajectory), ``dynamic`` (controllers),
``systems`` (our LeafSystems) and ``diagram`` (the wiring); ``learning`` above the
pipeline (the learned half), ``commands`` above all (one module a command). Their order
is a contract (docs/architecture.md).
"""

import os
import sys

__version__ = "0.1.0"

from cake_drake.paths import MODELS_DIR as MODELS_DIR  # noqa: E402 - the models/ folder


def started_as_command() -> bool:
    """Whether this process is a command: ``python -m cake_drake.<command>`` (Python
    imports this package first, with ``sys.argv[0]`` set to ``"-m"`` until the command's
    module runs) or the ``cake-drake`` console script."""
    first = (getattr(sys, "argv", None) or [""])[0]
    return first == "-m" or os.path.basename(first) == "cake-drake"


if started_as_command():  # before any command imports pydrake: Ctrl-C is one line, 130
    from cake_drake.errors import quiet_interrupts

    quiet_interrupts()
