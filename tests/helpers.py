"""What the tests share besides fixtures: the checkout's root, the test data and the
exercise's scenario. Every test module imports them from here (``from tests.helpers
import ...``); fixtures stay in ``conftest.py``."""

from __future__ import annotations

from pathlib import Path

from cake_drake.scenario import Scenario

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "tests" / "data"


def scenario(mode: str = "torque", problem=None, **outputs) -> Scenario:
    """The exercise's scenario with the shipped controller ``mode`` and, if given, a problem."""
    from cake_drake.scenario import controller_for_mode

    s = Scenario(controller=controller_for_mode(mode))
    if problem is not None:
        s.task.problem = str(problem)
    for key, value in outputs.items():
        setattr(s.outputs, key, value)
    return s
