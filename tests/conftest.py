"""Shared fixtures: one recorded reference trajectory for the whole session."""

from __future__ import annotations

import pytest

from cake_drake.pipeline import run
from cake_drake.scenario import JointPd, Scenario


def scenario(mode: str = "torque", problem=None, **outputs) -> Scenario:
    """The exercise's scenario with the shipped controller ``mode`` and, if given, a problem."""
    from cake_drake.scenario import controller_for_mode

    s = Scenario(controller=controller_for_mode(mode))
    if problem is not None:
        s.task.problem = str(problem)
    for key, value in outputs.items():
        setattr(s.outputs, key, value)
    return s


@pytest.fixture(scope="session")
def position_run(tmp_path_factory):
    """problem_5 executed in position mode, outputs written (the replay's reference)."""
    out = tmp_path_factory.mktemp("position_run")
    s = Scenario(controller=JointPd())
    s.outputs.folder, s.outputs.render = str(out), False
    result = run(s)
    assert result.success, result.message
    return out, result
