"""A residual for the last millimetres: PPO on one place at a time (CakeDrake/Skill-v0)
over the shipped relative skill, the folder it writes, and that folder run as any skill.

Everything is real: Drake, the planner, the relative skill, Stable-Baselines3 and torch.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cake_drake.learning.skills import residual as skill_rl
from tests.helpers import ROOT

SKILL = ROOT / "models" / "policies" / "skills"

TINY = """\
tiny:
  seed: 300000
  task: {{generate: {{blocks: 3}}}}
  world: {{placement: {{xy: 0.02, yaw_deg: 20.0}}}}
  motion: {{skills: "{skill}", skill_action_space: relative}}
  training:
    rl:
      algorithm: ppo
      base: "{skill}"
      steps: 128
      envs: 1
      rollout: 64
      batch_size: 32
      epochs: 1
      hidden_dims: [16, 16]
      residual_scale: 0.003
      log_std: -1.0
      eval_every: 64
      eval_episodes: 2
      starts: "{starts}"
      reward: {{goal: 1.0, success: 5.0, place: 0.05, step: -0.05, lost: -10.0}}
"""


def cake(command: str, *args: str, cwd: Path = ROOT):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", f"cake_drake.{command}", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=900, env=env)  # fmt: skip


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("skill_rl")
    (folder / "tiny.yaml").write_text(TINY.format(skill=SKILL, starts="pool.json"))
    r = cake("record", "tiny.yaml", "--name", "tiny", "--starts", "pool.json",
             "--episodes", "3", cwd=folder)  # fmt: skip
    assert r.returncode == 0 and "pool.json: 3 starts for CakeDrake/Skill-v0" in r.stdout, r.stderr
    # the training's episodes start from the pool; its held-out checks replay
    r = cake("train", "--rl", "tiny.yaml", "--name", "tiny", "--out", "out", cwd=folder)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "skill + RL residual (PPO) on tiny, 128 steps" in r.stdout, r.stdout
    return folder


def test_a_short_ppo_run_writes_its_folder_with_held_out_checks(trained):
    out = trained / "out"
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == sorted(
        skill_rl.FILES
    )
    info = json.loads((out / skill_rl.FILE).read_text())
    assert info["kind"] == "skill_residual" and info["steps"] == 128
    assert info["recipe"]["starts"] == "pool.json" and "pool.json" in info["episodes_of"]
    assert info["base"]["path"] == "package://cake_drake/policies/skills"
    assert info["base"]["sha256"] == skill_rl.digest(SKILL)
    # checks at 0 (the base alone), 64 and 128, each on the same two held-out places
    assert [c["steps"] for c in info["checks"]] == [0, 64, 128]
    assert all(c["of"] == 2 for c in info["checks"])
    assert info["kept"].startswith("the model of step ")
    skill_rl.check_folder(out)  # the one reader takes what the training wrote


def test_zero_residual_weights_give_the_skill_s_action_exactly(trained):
    from stable_baselines3 import PPO

    from cake_drake.learning.skills.relative import RelativeSkill

    residual = skill_rl.ResidualSkill(trained / "out")
    with __import__("torch").no_grad():
        net = residual.model.policy.action_net
        net.weight.zero_()
        net.bias.zero_()
    base = RelativeSkill(SKILL)
    rng = np.random.default_rng(0)
    residual.reset()
    for _ in range(20):
        relative = rng.normal(0, 0.05, 14).astype(np.float32)
        relative[:4] = np.eye(4)[rng.integers(4)]
        relative[13] = 0.08
        obs = {"observation.relative": relative}
        np.testing.assert_array_equal(residual.act(obs), base.act(obs))
    # and a bounded correction on the four moves alone, whatever the learner answers
    a = skill_rl.compose(np.arange(7.0), [5, -5, 0.5, 1], 0.003)
    np.testing.assert_allclose(a, [0.003, 0.997, 2.0015, 3, 4, 5.003, 6])
    assert PPO  # the learner's library is the one the folder names


def test_the_folder_runs_as_a_skill_and_says_so(trained, tmp_path):
    (tmp_path / "s.yaml").write_text(
        'task: {problem: "package://cake_drake/pddl/stack2.pddl"}\n'
        f"motion: {{skills: {trained / 'out'}}}\n"
        "outputs: {render: false}\n"
    )
    r = cake("run", "--scenario", "s.yaml", "--out", "run", cwd=tmp_path)
    assert r.returncode in (0, 3), r.stderr
    layers = json.loads((tmp_path / "run" / "summary.json").read_text())["layers"]
    assert "imitation + RL residual (PPO) on the hand's moves" in layers["geometric"]["what"]


def test_a_residual_for_another_base_is_refused_before_simulating(trained, tmp_path):
    moved = tmp_path / "out"
    shutil.copytree(trained / "out", moved)
    info = json.loads((moved / skill_rl.FILE).read_text())
    info["base"]["sha256"] = "0" * 64
    (moved / skill_rl.FILE).write_text(json.dumps(info))
    (tmp_path / "s.yaml").write_text(
        f'task: {{problem: "package://cake_drake/pddl/stack2.pddl"}}\nmotion: {{skills: {moved}}}\n'
    )
    r = cake("run", "--scenario", "s.yaml", "--out", "run", cwd=tmp_path)
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "a residual for another base skill" in r.stderr
    assert not (tmp_path / "run").exists()


def test_a_pool_of_another_skill_is_refused_before_anything_trains(trained, tmp_path):
    body = json.loads((trained / "pool.json").read_text())
    body["skill_digest"] = "0" * 64
    (tmp_path / "pool.json").write_text(json.dumps(body))
    (tmp_path / "tiny.yaml").write_text(TINY.format(skill=SKILL, starts="pool.json"))
    r = cake("train", "--rl", "tiny.yaml", "--name", "tiny", "--out", "out", cwd=tmp_path)
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "pool.json: drawn with another lead skill" in r.stderr
    assert not (tmp_path / "out").exists()


def test_a_skill_residual_on_a_skill_that_reads_the_arm_is_refused(tmp_path):
    joint = ROOT / "models" / "policies" / "skills_joint_space"
    (tmp_path / "tiny.yaml").write_text(
        TINY.format(skill=SKILL, starts="").replace(f'base: "{SKILL}"', f'base: "{joint}"')
    )
    r = cake("train", "--rl", "tiny.yaml", "--name", "tiny", "--out", "out", cwd=tmp_path)
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "training.rl.base" in r.stderr and "corrects a skill that never sees the arm" in r.stderr
    assert not (tmp_path / "out").exists()
