"""Shared fixtures: one recorded reference trajectory for the whole session."""

from __future__ import annotations

import pytest

from cake_drake.diagram import RunConfig
from cake_drake.run import run


@pytest.fixture(scope="session")
def position_run(tmp_path_factory):
    """problem_5 executed in position mode, outputs written (the replay's reference)."""
    out = tmp_path_factory.mktemp("position_run")
    result = run(RunConfig(mode="position"), out=out, render=False)
    assert result.success, result.message
    return out, result
