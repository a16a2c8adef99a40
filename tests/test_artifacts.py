"""The table of learned kinds (cake_drake.artifacts): each shipped folder's kind decided
from the files it has, a folder of another kind refused in one line, and each described
by its own kind's describer."""

from __future__ import annotations

import re
import shutil

import pytest

from cake_drake import artifacts
from cake_drake.errors import InputError
from tests.helpers import ROOT

MODELS = ROOT / "models"


@pytest.mark.parametrize(
    ("folder", "kind", "words"),
    [
        ("policies/stack2", "policy", "imitation, cake_mlp"),
        (
            "policies/skills_joint_space",
            "skill",
            "reads the arm's joints, answers in joint_position",
        ),
        ("policies/skills", "relative_skill", "reads the action from the hand"),
        ("policies/stack2_pixels_rl", "rl", "imitation + RL residual, PPO"),
        ("planners/blocks", "planner", "relational network, width 64"),
        ("residuals/cubes_0.5kg", "residual", "residual fitted on 5 runs"),
    ],
)
def test_each_shipped_learned_part_is_of_its_kind_and_described_by_it(folder, kind, words):
    assert artifacts.detect(MODELS / folder).name == kind
    assert words in artifacts.describe(MODELS / folder)


def test_a_training_folder_is_its_last_checkpoints_kind(tmp_path):
    last = tmp_path / "run" / "checkpoints" / "last" / "pretrained_model"
    shutil.copytree(MODELS / "policies" / "skills_joint_space", last)
    assert artifacts.detect(tmp_path / "run").name == "skill"


def test_another_kind_or_none_is_one_line_naming_the_folder(tmp_path):
    with pytest.raises(InputError, match=r"blocks: a learned planner \(planner.json\), not a "
                       r"whole-task policy"):  # fmt: skip
        artifacts.require(MODELS / "planners" / "blocks", "policy", role="evaluate")
    with pytest.raises(InputError, match="not a LeRobot checkpoint .* nor another learned part"):
        artifacts.detect(MODELS / "pddl")
    with pytest.raises(InputError, match="no such folder"):
        artifacts.detect(tmp_path / "nothing")
    assert artifacts.kind_of(tmp_path) is None


def test_evaluate_refuses_a_planner_folder_before_any_episode(tmp_path):
    import subprocess
    import sys

    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.evaluate", str(MODELS / "planners" / "blocks"),
         "--suite", str(MODELS / "scenarios" / "learning.yaml"), "--name", "stack2",
         "--episodes", "1", "--out", str(tmp_path / "ev")],
        capture_output=True, text=True, cwd=ROOT, timeout=300,
    )  # fmt: skip
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "a learned planner (planner.json), not a whole-task policy" in r.stderr
    assert not (tmp_path / "ev").exists()


@pytest.mark.parametrize(
    ("yaml", "words"),
    [
        (
            "reference: !Policy {checkpoint: package://cake_drake/policies/skills}",
            "a skill that never sees the arm (skill.json), not a whole-task policy",
        ),
        (
            "reference: !Policy {checkpoint: package://cake_drake/planners/blocks}",
            "a learned planner (planner.json), not a whole-task policy",
        ),
        (
            "motion: {skills: package://cake_drake/planners/blocks}",
            "a learned planner (planner.json), not a learned skill",
        ),
        (
            "motion: {skills: package://cake_drake/policies/stack2}",
            "a whole-task policy (a LeRobot checkpoint), not a learned skill",
        ),
    ],
    ids=["skill-as-policy", "planner-as-policy", "planner-as-skills", "policy-as-skills"],
)
def test_the_policy_and_skill_doors_name_the_kind_they_were_given(tmp_path, yaml, words):
    from cake_drake.pipeline import check
    from cake_drake.scenario import load_scenario

    (tmp_path / "s.yaml").write_text(yaml + "\n")
    with pytest.raises(InputError, match=re.escape(words)):
        check(load_scenario(tmp_path / "s.yaml"), write=False)
