"""cake_drake: the classical robot-manipulation cake as one Drake systems diagram.

Layers (one sub-package each): ``symbolic`` (PDDL -> plan), ``world`` (the scene),
``geometric`` (waypoints -> IK -> joint trajectory), ``dynamic`` (controllers),
``systems`` (our LeafSystems) and ``diagram`` (the wiring).
"""

from pathlib import Path

__version__ = "0.1.0"

#: Repository folder that holds the scene, robot and PDDL files.
MODELS_DIR = Path(__file__).resolve().parent.parent / "models"
