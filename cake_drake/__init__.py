"""cake_drake: the classical robot-manipulation cake as one Drake systems diagram.

Layers (one sub-package each): ``symbolic`` (PDDL -> plan), ``world`` (the scene),
``geometric`` (waypoints -> IK -> joint trajectory), ``dynamic`` (controllers),
``systems`` (our LeafSystems) and ``diagram`` (the wiring).
"""

import os
import sys
from pathlib import Path

__version__ = "0.1.0"

#: Repository folder that holds the scene, robot and PDDL files.
MODELS_DIR = Path(__file__).resolve().parent.parent / "models"


def started_as_command() -> bool:
    """Whether this process is a command: ``python -m cake_drake.<command>`` (Python
    imports this package first, with ``sys.argv[0]`` set to ``"-m"`` until the command's
    module runs) or the ``cake-drake`` console script."""
    first = (getattr(sys, "argv", None) or [""])[0]
    return first == "-m" or os.path.basename(first) == "cake-drake"


if started_as_command():  # before any command imports pydrake: Ctrl-C is one line, 130
    from cake_drake.errors import quiet_interrupts

    quiet_interrupts()
