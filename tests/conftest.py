"""Shared fixtures: one recorded reference trajectory for the whole session (the shared
helpers are in ``tests/helpers.py``)."""

from __future__ import annotations

import pytest

from cake_drake.pipeline import run
from cake_drake.scenario import JointPd, Scenario


@pytest.fixture(scope="session")
def position_run(tmp_path_factory):
    """problem_5 executed in position mode, outputs written (the replay's reference)."""
    out = tmp_path_factory.mktemp("position_run")
    s = Scenario(controller=JointPd())
    s.outputs.folder, s.outputs.render = str(out), False
    result = run(s)
    assert result.success, result.message
    return out, result
