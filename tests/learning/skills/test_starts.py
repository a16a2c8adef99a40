"""Start pools for ``CakeDrake/Skill-v0``: a start restored from the file is the start the
lead's replayed actions reached, number for number, and a pool that does not belong to
the environment is refused in one line (Drake, the planner and the skill all real)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cake_drake.errors import InputError
from cake_drake.learning.skills import starts
from cake_drake.learning.skills.env import SkillEnv
from cake_drake.learning.skills.relative import RelativeSkill
from tests.helpers import ROOT

SKILL = ROOT / "models" / "policies" / "skills"
LEARNING = ROOT / "models" / "scenarios" / "learning.yaml"
KW = {"blocks": (3, 4), "cube_mass_range_kg": (0.05, 0.5)}
STEPS = 12


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """Three replayed starts, each with the observations the skill's own answers gave."""
    env = SkillEnv(**KW)
    runs, pool = [], []
    for seed in (5, 6, 7):
        obs, _ = env.reset(seed=seed)
        pool.append(env.start())
        skill = RelativeSkill(SKILL)
        skill.restore(env.start().lead)
        seen, answers = [obs], []
        for _ in range(STEPS):
            answers.append(skill.act({"observation.relative": seen[-1]}))
            obs, _, terminated, truncated, _ = env.step(answers[-1])
            seen.append(obs)
            if terminated or truncated:
                break
        runs.append((seen, answers))
    path = tmp_path_factory.mktemp("pool") / "pool.json"
    starts.write(path, starts.settings_of(env), env.skill_digest, pool)
    return path, runs


def test_a_restored_start_is_the_replayed_one_number_for_number(recorded):
    path, runs = recorded
    env = SkillEnv(**KW, starts=str(path))
    assert len(env._pool) == 3
    seen_starts = set()
    for seed in range(12):  # reset draws from the pool; each start's steps are the replayed
        obs, info = env.reset(seed=seed)
        k = next(i for i, s in enumerate(env._pool) if s is env.start())
        seen_starts.add(k)
        replayed, answers = runs[k]
        np.testing.assert_array_equal(obs, replayed[0])
        assert info["steps"] == 0 and info["action"] in ("stack", "put-down")
        if seed < 6:
            for answer, then in zip(answers, replayed[1:], strict=True):
                obs, *_ = env.step(answer)
                np.testing.assert_array_equal(obs, then)
    assert len(seen_starts) >= 2  # more than one start drawn (and Diagrams reused)


def test_recorded_starts_are_several_a_problem_and_restore_to_the_same_steps(tmp_path):
    env = SkillEnv(**KW)
    pool = env.record(5, seed=40)
    problems = {(s.seed, s.blocks) for s in pool}
    assert len(problems) < 5 and env.start() is pool[-1]
    path = tmp_path / "pool.json"
    starts.write(path, starts.settings_of(env), env.skill_digest, pool)
    again = SkillEnv(**KW, starts=str(path))
    again._pool = again._pool[-1:]  # the start the recording environment stands at
    obs, _ = again.reset(seed=0)
    one, other = RelativeSkill(SKILL), RelativeSkill(SKILL)
    one.restore(pool[-1].lead)
    other.restore(pool[-1].lead)
    here = obs
    for _ in range(STEPS):  # the same answers to the same observations, step for step
        a = one.act({"observation.relative": here})
        b = other.act({"observation.relative": obs})
        np.testing.assert_array_equal(a, b)
        here, _, ended, _, _ = env.step(a)
        obs, *_ = again.step(b)
        np.testing.assert_array_equal(here, obs)
        if ended:
            break


def test_a_start_holds_the_whole_state_and_reads_back_equal(recorded):
    path, _ = recorded
    env = SkillEnv(**KW)
    pool = starts.read(path, starts.settings_of(env), env.skill_digest, str(SKILL))
    body = json.loads(path.read_text())
    assert body["kind"] == starts.KIND and body["skill_digest"] == starts.digest(SKILL)
    first = pool[0]
    assert {type(v).__name__ for v in first.abstract.values()} == {"MonitorState", "SkillProgress"}
    progress = next(v for v in first.abstract.values() if type(v).__name__ == "SkillProgress")
    assert progress.steps == 1 and progress.context.schema in ("stack", "put-down")
    assert len(first.discrete) >= 2 and first.continuous.size == 7  # the controller's integral
    again = starts.decode(starts.encode(progress), "here")
    assert again.context.target.tolist() == progress.context.target.tolist()
    assert (again.action, again.working, again.hand) == (progress.action, progress.working,
                                                          progress.hand)  # fmt: skip


def _bad(path, tmp_path, change) -> str:
    body = json.loads(path.read_text())
    text = change(body)
    bad = tmp_path / "bad.json"
    bad.write_text(text if isinstance(text, str) else json.dumps(body))
    with pytest.raises(InputError) as e:
        SkillEnv(**KW, starts=str(bad))
    message = str(e.value)
    assert "\n" not in message and str(bad) in message
    return message


def test_a_pool_of_another_skill_or_task_is_refused_when_made(recorded, tmp_path):
    path, _ = recorded

    def other_skill(b):
        b["skill_digest"] = "0" * 64

    assert "drawn with another lead skill" in _bad(path, tmp_path, other_skill)

    def other_masses(b):
        b["settings"]["cube_mass_range_kg"] = [0.05, 0.06]

    said = _bad(path, tmp_path, other_masses)
    assert "settings.cube_mass_range_kg is [0.05, 0.06]" in said and "[0.05, 0.5]" in said

    def other_cubes(b):
        b["settings"]["blocks"] = [3, 8]

    assert "settings.blocks is [3, 8]" in _bad(path, tmp_path, other_cubes)


def test_an_empty_truncated_or_non_finite_pool_is_refused(recorded, tmp_path):
    path, _ = recorded

    def empty(b):
        b["starts"] = []

    assert "holds no start" in _bad(path, tmp_path, empty)
    assert "unreadable" in _bad(path, tmp_path, lambda b: path.read_text()[:5000])

    def nan(b):
        b["starts"][1]["discrete"][0][3] = float("nan")

    assert "starts[1].discrete[0]: expected a list of finite numbers" in _bad(path, tmp_path, nan)

    def foreign(b):
        b["starts"][0]["abstract"]["1"] = {"type": "Popen", "fields": {}}

    assert "starts[0].abstract.1" in _bad(path, tmp_path, foreign)


def test_without_a_pool_start_is_refused_before_a_reset():
    env = SkillEnv(**KW)
    with pytest.raises(RuntimeError, match=r"reset\(\) before start\(\)"):
        env.start()


def test_record_keeps_a_file_that_exists_and_refuses_a_task_with_no_skill_residual(tmp_path):
    import os
    import subprocess
    import sys

    def record(*args):
        return subprocess.run(
            [sys.executable, "-m", "cake_drake.record", str(LEARNING), *args],
            cwd=tmp_path, capture_output=True, text=True, timeout=300,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
        )  # fmt: skip

    (tmp_path / "mine.json").write_text("mine")
    r = record("--name", "skills_rl", "--starts", "mine.json")
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "--starts mine.json: exists; give a path to a new file" in r.stderr
    assert (tmp_path / "mine.json").read_text() == "mine"
    r = record("--name", "stack2", "--starts", "new.json", "--episodes", "1")
    assert r.returncode == 2 and "a skill residual corrects a skill that never sees" in r.stderr
    assert not (tmp_path / "new.json").exists()
