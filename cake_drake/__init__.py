"""cake_drake: the classical robot-manipulation cake as one Drake systems diagram.

Layers (one sub-package each): ``symbolic`` (PDDL -> plan), ``world`` (the scene),
``perception`` (the cubes from the cameras), ``geometric`` (waypoints -> IK -> joint
trajectory), ``dynamic`` (controllers), ``systems`` (our LeafSystems), ``policy`` (a
learned policy's slot in the Diagram), ``language`` (SayCan transcripts onto PDDL);
``learning`` above the pipeline (the learned half), ``outputs`` (what a run shows),
``sweeps`` and ``gains`` (many runs), ``commands`` above all (one module a command).
Their order is a contract (docs/architecture.md).

Beside them, one module a door: ``scenario`` (a run as data), ``pipeline`` (a run as a
library call), ``diagram`` (the one wiring), ``execution`` (simulating it), ``plugins``
(every implementation's door), ``artifacts`` (the learned kinds), ``formats`` and
``paths`` (the files), ``errors`` (exit codes), ``processes`` (owned process groups) and
``gym`` (the Gymnasium environments). ``run``, ``plan``, ``validate``, ``saycan``,
``sweep``, ``record``, ``evaluate`` and ``train`` are ``python -m cake_drake.COMMAND``;
``cli`` is the ``cake-drake`` console script.
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
