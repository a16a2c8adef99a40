"""Learned skills under the classical top: the ground action recorded per frame, a skill
trained through LeRobot's loop on the per-action segments, run as the geometric layer
beside the planner and the execution monitor (a run, evaluate), each layer labelled.

Real recordings (Drake, the closed-loop expert, lerobot's writer), LeRobot's training
loop, the shipped skills.
"""

from __future__ import annotations

import json
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cake_drake.policy.shield import DEFAULT
from tests.helpers import ROOT

LEARNING = ROOT / "models" / "scenarios" / "learning.yaml"
SHIPPED = ROOT / "models" / "policies" / "skills"
#: The skills that read the arm's joints, kept beside the shipped ones as the comparison.
JOINT_SPACE = ROOT / "models" / "policies" / "skills_joint_space"
#: What a run's layers say of the shipped skills with every shield step.
DESCRIBED = (
    "imitation, reads the action from the hand (never the arm), answers hand moves "
    "with IK below and a gripper decision, shield of 13 steps"
)

pytestmark = pytest.mark.slow


def cli(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", *args], cwd=ROOT, capture_output=True, text=True,
        timeout=timeout, env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    """Two demonstrations of the skills task (generated five-cube problems), no cameras."""
    out = tmp_path_factory.mktemp("skills") / "ds"
    r = cli("cake_drake.record", str(LEARNING), "--name", "skills", "--episodes", "2",
            "--no-cameras", "--workers", "1", "--out", str(out))  # fmt: skip
    assert r.returncode == 0, r.stderr
    return out


@pytest.fixture(scope="module")
def skill(recording, tmp_path_factory) -> Path:
    """A skill trained a few steps with the task's recipe (--inputs skill, from report.json)."""
    out = tmp_path_factory.mktemp("skill") / "train"
    r = cli("cake_drake.train", str(recording), "--out", str(out), "--steps", "20",
            "--batch-size", "32")  # fmt: skip
    assert r.returncode == 0, r.stderr
    config = json.loads((out / "checkpoints/last/pretrained_model/config.json").read_text())
    assert set(config["input_features"]) == {"observation.state", "observation.skill"}
    return out


@pytest.fixture(scope="module")
def hand_skill(tmp_path_factory) -> Path:
    """A skill that answers moves of the hand (the skills_hand task: ee_delta), trained a
    few steps on two demonstrations."""
    base = tmp_path_factory.mktemp("hand")
    r = cli("cake_drake.record", str(LEARNING), "--name", "skills_hand", "--episodes", "2",
            "--no-cameras", "--workers", "1", "--out", str(base / "ds"))  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "ee_delta" in r.stdout
    r = cli("cake_drake.train", str(base / "ds"), "--out", str(base / "train"), "--steps", "20",
            "--batch-size", "32")  # fmt: skip
    assert r.returncode == 0, r.stderr
    model = base / "train" / "checkpoints" / "last" / "pretrained_model"
    config = json.loads((model / "config.json").read_text())
    assert config["output_features"]["action"]["shape"] == [7]
    return base / "train"


def scenario_file(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "scenario.yaml"
    path.write_text(body)
    return path


def test_the_ground_action_is_recorded_per_frame_and_cuts_the_recording(recording):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from cake_drake.learning.data.batches import ColumnDataset
    from cake_drake.policy.observations import SKILL_SCHEMAS

    chunk = {"action": [k / 10 for k in range(10)], "observation.state": [-0.1, 0.0]}
    base = LeRobotDataset("cake_drake/stack", root=recording, delta_timestamps=chunk,
                          video_backend="pyav")  # fmt: skip
    # Not an observation.* key: LeRobot's own tools take it for no policy's input.
    assert base.meta.features["skill"]["shape"] == (13,)
    assert not any(k.startswith("observation.skill") for k in base.meta.features)
    data = ColumnDataset(base, ["observation.state", "observation.skill"])
    ground = data.columns["ground_action"]
    episode = data.columns["episode_index"]
    report = json.loads((recording / "report.json").read_text())
    # Every ground action of the expert's plan shows, in order, one segment each.
    for k in range(report["episodes"]):
        rows = ground[episode == k]
        under_way = rows[rows[:, 0] >= 0]
        changes = np.flatnonzero(np.any(np.diff(under_way, axis=0) != 0, axis=1))
        segments = [under_way[0], *under_way[changes + 1]]
        assert [int(s[3]) for s in segments] == list(range(len(segments)))
        schemas = {SKILL_SCHEMAS[int(s[0])] for s in segments}
        assert schemas <= set(SKILL_SCHEMAS) and len(segments) >= 2
        # observation.skill one-hot says the same schema as ground_action.
        skills = data.columns["observation.skill"][episode == k][rows[:, 0] >= 0]
        assert np.array_equal(np.argmax(skills[:, :4], axis=1), under_way[:, 0])
    # A segment's last frame: its action chunk stops at the segment, padded as at an
    # episode's end; its first frame: the history is padded before it.
    boundary = np.flatnonzero(np.any(np.diff(ground, axis=0) != 0, axis=1))
    last = int(boundary[1])  # the first ground action's last frame (after the wait, if any)
    if episode[last] != episode[last + 1]:
        pytest.skip("no boundary inside an episode")  # the fixture always has one
    sample = data[last]
    assert sample["action_is_pad"].tolist() == [False] + [True] * 9
    action = sample["action"].numpy()
    assert np.array_equal(action[1:], np.repeat(action[:1], 9, axis=0))
    first = data[last + 1]
    assert first["observation.skill_is_pad"].tolist() == [True, False]
    # LeRobot's own reading of the same frame crosses into the next action: only the cut
    # stops there.
    assert not base[last]["action_is_pad"][1]


def test_a_skill_runs_under_the_planner_and_the_monitor_handles_its_failure(skill, tmp_path):
    out = tmp_path / "run"
    path = scenario_file(tmp_path, f"""
short:
  task: {{problem: "package://cake_drake/pddl/stack2.pddl"}}
  motion: {{skills: "{skill}", skill_max_steps: 15}}
  outputs: {{render: false}}
""")  # fmt: skip
    r = cli("cake_drake.run", "--scenario", str(path), "--name", "short", "--out", str(out))
    assert r.returncode == 3, r.stderr
    assert "did not do (pick-up a) in 3 tries of 15 steps each" in r.stderr
    assert "geometric learned (skills, imitation, cake_mlp, reads the arm's joints" in r.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["layers"]["geometric"]["kind"] == "learned"
    assert summary["layers"]["symbolic"]["kind"] == "classical"
    assert summary["skills"]["budget_ran_out"] == 3 and summary["skills"]["steps"] == 45
    assert summary["repeats"] == 3  # after each ending without its effects, the monitor repeats it


def test_a_skill_that_moves_the_hand_runs_under_the_planner_and_in_evaluate(hand_skill, tmp_path):
    path = scenario_file(tmp_path, f"""
short:
  task: {{problem: "package://cake_drake/pddl/stack2.pddl"}}
  motion: {{skills: "{hand_skill}", skill_max_steps: 15, skill_smooth_s: 0.2}}
  outputs: {{render: false}}
""")  # fmt: skip
    out = tmp_path / "run"
    r = cli("cake_drake.run", "--scenario", str(path), "--name", "short", "--out", str(out))
    assert r.returncode == 3, r.stderr  # a few training steps do not pick a cube
    assert "did not do (pick-up a) in 3 tries of 15 steps each" in r.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["skills"]["action_space"] == "ee_delta" and summary["skills"]["steps"] == 45
    # The hand moved: its joints are not where they started.
    q = np.load(out / "trajectory.npz")["q"]
    assert np.abs(q[-1] - q[0]).max() > 1e-3
    r = cli("cake_drake.evaluate", str(hand_skill), "--suite", str(LEARNING), "--name",
            "stack2", "--episodes", "1", "--seed", "100000", "--workers", "1", "--out",
            str(tmp_path / "eval"))  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "eval" / "summary.json").read_text())["episodes"] == 1


def test_a_relative_skill_trained_a_few_steps_runs_under_the_planner_and_in_evaluate(
    hand_skill, tmp_path
):
    """The recording of the hand's moves trains a skill that never sees the arm
    (--inputs relative); it runs as the geometric layer and in evaluate, and the run's
    layers say what it reads and answers."""
    out = tmp_path / "relative"
    r = cli("cake_drake.train", str(hand_skill.parent / "ds"), "--inputs", "relative",
            "--steps", "50", "--batch-size", "32", "--out", str(out))  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "relative skill trained 50 steps" in r.stdout
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == [
        "skill.json",
        "weights.npz",
    ]
    path = scenario_file(tmp_path, f"""
short:
  task: {{problem: "package://cake_drake/pddl/stack2.pddl"}}
  motion: {{skills: "{out}", skill_max_steps: 15, skill_action_space: relative}}
  simulation: {{max_sim_s: 6.0}}
  outputs: {{render: false}}
""")  # fmt: skip
    run = tmp_path / "run"
    r = cli("cake_drake.run", "--scenario", str(path), "--name", "short", "--out", str(run))
    assert r.returncode in (0, 3), r.stderr  # 50 steps may or may not pick the cube
    summary = json.loads((run / "summary.json").read_text())
    geometric = summary["layers"]["geometric"]
    assert geometric["kind"] == "learned"
    assert "reads the action from the hand (never the arm)" in geometric["what"]
    assert "answers hand moves with IK below and a gripper decision" in geometric["what"]
    assert summary["skills"]["action_space"] == "ee_delta" and summary["skills"]["steps"] > 0
    q = np.load(run / "trajectory.npz")["q"]
    assert np.abs(q[-1] - q[0]).max() > 1e-3  # the hand moved, IK below turning it into joints
    r = cli("cake_drake.evaluate", str(out), "--suite", str(LEARNING), "--name",
            "stack2", "--episodes", "1", "--seed", "100000", "--workers", "1", "--out",
            str(tmp_path / "eval"))  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "eval" / "summary.json").read_text())["episodes"] == 1


def test_a_skill_run_as_another_action_space_is_refused_before_simulating(
    skill, hand_skill, tmp_path
):
    for path, asked, trained in ((skill, "ee_delta", "joint_position"),
                                 (hand_skill, "joint_position", "ee_delta")):  # fmt: skip
        spec = scenario_file(tmp_path, f"""
wrong:
  motion: {{skills: "{path}", skill_action_space: {asked}}}
""")  # fmt: skip
        out = tmp_path / f"out_{asked}"
        r = cli("cake_drake.run", "--scenario", str(spec), "--name", "wrong", "--out", str(out))
        assert r.returncode == 2, r.stderr
        line = r.stderr.strip()
        assert len(line.splitlines()) == 1
        assert f"a skill trained on {trained} actions" in line and f"give {trained}" in line
        assert not out.exists()
    spec = scenario_file(
        tmp_path, f'wrong:\n  motion: {{skills: "{skill}", skill_action_space: joints}}\n'
    )
    r = cli("cake_drake.run", "--scenario", str(spec), "--name", "wrong", "--out",
            str(tmp_path / "x"))  # fmt: skip
    assert r.returncode == 2 and "one of joint_position, ee_delta" in r.stderr, r.stderr


def test_dagger_for_skills_labels_each_frame_with_the_action_under_way(hand_skill, tmp_path):
    """One short round: the skills act under the expert's choice of action, the expert
    labels every frame, and each frame says which ground action it belongs to."""
    from cake_drake.policy.observations import SKILL_SCHEMAS

    data, out = hand_skill.parent / "ds", tmp_path / "dagger"
    r = cli("cake_drake.train", str(data), "--out", str(out), "--steps", "20", "--batch-size",
            "32", "--dagger", "1", "--episodes-per-round", "1", "--round-steps", "20",
            "--beta", "0.5", "--workers", "1")  # fmt: skip
    assert r.returncode == 0, r.stderr
    (row,) = json.loads((out / "train.json").read_text())["dagger"]["rounds"]
    assert 0 < row["learner_frames"] < row["frames_added"]
    (seed,) = row["seeds"]
    with np.load(out / "rollouts" / f"ep_{seed}.npz") as z:
        grounds, skills, actors = z["grounds"], z["skills"], z["actors"]
        assert z["actions"].shape[1] == 7  # the teacher's labels, in the skill's ee_delta
    under_way = grounds[:, 0] >= 0
    assert under_way.sum() > 0.8 * len(grounds)
    # The skill's one-hot names the same schema as the frame's ground action, learner's
    # frames and expert's alike.
    assert np.array_equal(np.argmax(skills[under_way, :4], axis=1), grounds[under_way, 0])
    assert set(actors[under_way].tolist()) == {0, 1}
    assert {SKILL_SCHEMAS[int(k)] for k in grounds[under_way, 0]} <= set(SKILL_SCHEMAS)
    # The checkpoint of the last round is a skill, as any training's.
    config = json.loads((out / "checkpoints/last/pretrained_model/config.json").read_text())
    assert "observation.skill" in config["input_features"]


#: docs/learning.md's DAgger for a skill that never sees the arm, run as the page shows it.
RELATIVE_DAGGER = "python -m cake_drake.train hand_demos --inputs relative --out relative_dagger --steps 30 --batch-size 32 --dagger 1 --episodes-per-round 1 --beta 0.8 --workers 1"  # noqa: E501 - verbatim


def test_dagger_for_a_relative_skill_labels_the_network_alone_s_states_and_trains_afresh(
    hand_skill, tmp_path
):
    """--dagger with --inputs relative: the skill that never sees the arm acts with no
    shield step under the expert's choice of action, the expert labels its frames, and
    each round trains a skill afresh on every frame so far; OUT is the last round's skill,
    which a run takes as motion.skills."""
    (tmp_path / "hand_demos").symlink_to(hand_skill.parent / "ds")
    out = tmp_path / "relative_dagger"
    r = subprocess.run(
        [sys.executable, *shlex.split(RELATIVE_DAGGER)[1:]], cwd=tmp_path, capture_output=True,
        text=True, timeout=600, env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "round 1: 1 episodes" in r.stdout
    assert "1 rounds of DAgger" in r.stdout and "motion.skills: relative_dagger" in r.stdout
    assert "trained afresh 30 steps" in r.stdout
    assert {p.name for p in out.iterdir() if not p.name.startswith(".")} == {
        "skill.json", "weights.npz", "train.json", "rounds", "data", "rollouts",
    }  # fmt: skip
    summary = json.loads((out / "train.json").read_text())
    (row,) = summary["dagger"]["rounds"]
    assert 0 < row["learner_frames"] < row["frames_added"]
    assert summary["phases_s"]["training"] > 0
    first = json.loads((out / "rounds" / "round-0" / "skill.json").read_text())
    last = json.loads((out / "skill.json").read_text())
    assert last["kind"] == "relative_skill"
    # Round 1 learned from more frames than the recording alone: the learner's, labelled.
    assert last["recipe"]["frames"] > first["recipe"]["frames"]
    assert (out / "weights.npz").read_bytes() == (out / "rounds/round-1/weights.npz").read_bytes()
    (seed,) = row["seeds"]
    with np.load(out / "rollouts" / f"ep_{seed}.npz") as z:
        assert z["actions"].shape[1] == 7 and set(z["actors"].tolist()) == {0, 1}
    from cake_drake.learning.skills.relative import check_folder

    check_folder(out)


def test_a_relative_dagger_that_cannot_work_is_one_line_before_any_rollout(hand_skill, tmp_path):
    data = tmp_path / "ds"
    shutil.copytree(hand_skill.parent / "ds", data)
    base = ("cake_drake.train", str(data), "--inputs", "relative", "--dagger", "1")
    for flags, words in (
        (("--policy", "act"), "--policy act with --inputs relative"),
        (("--device", "cuda"), "--device cuda with --inputs relative: it trains on the CPU"),
    ):
        r = cli(*base, *flags, "--out", str(tmp_path / "d"))
        assert r.returncode == 2 and words in r.stderr, r.stderr
        assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "d").exists()
    (data / "report.json").unlink()
    r = cli(*base, "--out", str(tmp_path / "d"))
    assert r.returncode == 2 and "report.json: missing; --dagger rolls" in r.stderr, r.stderr
    r = cli("cake_drake.train", str(data), "--inputs", "relative", "--out", str(tmp_path / "d"))
    assert r.returncode == 2, r.stderr
    assert "policy act (the recipe of" in r.stderr and "(--policy mlp)" in r.stderr
    assert not (tmp_path / "d").exists()


def test_dagger_for_skills_with_a_teacher_that_cannot_label_per_action_is_refused(
    hand_skill, tmp_path
):
    data = tmp_path / "ds"
    shutil.copytree(hand_skill.parent / "ds", data)
    report = json.loads((data / "report.json").read_text())
    report["spec"]["policy"] = "examples.random_policy:make"
    (data / "report.json").write_text(json.dumps(report))
    r = cli("cake_drake.train", str(data), "--out", str(tmp_path / "d"), "--steps", "2",
            "--dagger", "1", "--episodes-per-round", "1", "--workers", "1")  # fmt: skip
    assert r.returncode == 2, r.stderr
    line = r.stderr.strip()
    assert len(line.splitlines()) == 1
    assert "examples.random_policy:make cannot say which ground action" in line
    assert "skill_observation()" in line
    assert not (tmp_path / "d").exists()


def test_skill_settings_that_cannot_work_are_refused_before_simulating(tmp_path):
    for motion, words in (
        ("skill_ensemble: 0.01, skill_device: cuda", "the ensembled skill acts in NumPy"),
        ("skill_ensemble: -1", "motion.skill_ensemble = -1.0 is outside 0 to 10"),
        ("skill_smooth_s: 9", "motion.skill_smooth_s = 9.0 is outside 0 to 5 s"),
    ):  # fmt: skip
        spec = scenario_file(tmp_path, f"""
bad:
  motion: {{skills: "package://cake_drake/policies/skills_joint_space", {motion}}}
""")  # fmt: skip
        out = tmp_path / "out"
        r = cli("cake_drake.run", "--scenario", str(spec), "--name", "bad", "--out", str(out))
        assert r.returncode == 2 and words in r.stderr, r.stderr
        assert len(r.stderr.strip().splitlines()) == 1 and not out.exists()


def test_skill_settings_are_checked_without_skills_too():
    # Every number of a scenario is checked before any work, read or not: a setting of
    # the learned skills, given where the classical layer runs, is refused all the same.
    import re

    from cake_drake.errors import InputError
    from cake_drake.pipeline import check
    from cake_drake.scenario import parse_scenario

    for motion, words in (
        ("skill_smooth_s: 9", "motion.skill_smooth_s = 9.0 is outside 0 to 5 s"),
        ("skill_ensemble: -1", "motion.skill_ensemble = -1.0 is outside 0 to 10"),
        ("skill_rate_hz: 0", "motion.skill_rate_hz = 0.0 is outside 0.5 to 100 Hz"),
        ("skill_action_space: joints", "motion.skill_action_space: 'joints'"),
    ):  # fmt: skip
        s = parse_scenario(f"motion: {{{motion}}}\n")
        with pytest.raises(InputError, match=re.escape(words)):
            check(s, write=False)


def test_evaluate_runs_a_skill_checkpoint_under_the_named_scenarios_planner(skill, tmp_path):
    out = tmp_path / "eval"
    r = cli("cake_drake.evaluate", str(skill), "--suite", str(LEARNING), "--name", "stack2",
            "--episodes", "1", "--seed", "100000", "--workers", "1", "--out", str(out))  # fmt: skip
    assert r.returncode == 0, r.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["episodes"] == 1 and "monitor" in summary
    assert "repeats" in (out / "results.csv").read_text().splitlines()[0]


def test_a_skill_and_a_whole_task_policy_are_not_taken_for_each_other(skill, tmp_path):
    as_policy = scenario_file(tmp_path, f"""
wrong:
  reference: !Policy {{checkpoint: "{skill}"}}
""")  # fmt: skip
    r = cli("cake_drake.run", "--scenario", str(as_policy), "--name", "wrong", "--out",
            str(tmp_path / "a"))  # fmt: skip
    assert r.returncode == 2 and "a learned skill" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    (tmp_path / "b").mkdir()
    as_skill = tmp_path / "b" / "s.yaml"
    as_skill.write_text('wrong:\n  motion: {skills: "package://cake_drake/policies/stack2"}\n')
    r = cli("cake_drake.run", "--scenario", str(as_skill), "--name", "wrong", "--out",
            str(tmp_path / "c"))  # fmt: skip
    assert r.returncode == 2 and "a whole-task policy" in r.stderr, r.stderr
    assert not (tmp_path / "c").exists()  # refused before anything ran


def test_a_skill_that_answers_nan_stops_the_run_naming_it(skill, tmp_path):
    import torch
    from safetensors.torch import load_file, save_file

    bad = tmp_path / "nan_skill"
    shutil.copytree(skill / "checkpoints" / "last" / "pretrained_model", bad)
    weights = load_file(str(bad / "model.safetensors"))
    weights = {k: (v * float("nan") if k.startswith("net.") else v) for k, v in weights.items()}
    save_file({k: v.contiguous() for k, v in weights.items()}, str(bad / "model.safetensors"))
    assert torch.isnan(load_file(str(bad / "model.safetensors"))["net.0.weight"]).all()
    path = scenario_file(tmp_path, f'nan:\n  motion: {{skills: "{bad}"}}\n')
    r = cli("cake_drake.run", "--scenario", str(path), "--name", "nan", "--out",
            str(tmp_path / "out"))  # fmt: skip
    assert r.returncode == 3, r.stderr
    line = r.stderr.strip().splitlines()[-1]
    assert "nan_skill" in line and "(unstack a b)" in line and "8 finite numbers" in line


def test_each_layer_is_labelled_classical_or_learned():
    from cake_drake.outputs.report import layers, layers_line
    from cake_drake.scenario import load_scenario

    classical = load_scenario(ROOT / "models" / "scenarios" / "exercise.yaml", "torque")
    text = layers_line(layers(classical, None))
    assert text.startswith("layers: symbolic classical (")
    assert "geometric classical (waypoints, IK (drake), straight moves)" in text
    assert "dynamic classical (computed torque, InverseDynamicsController)" in text
    whole = layers(load_scenario(LEARNING, "learned_stack2"), None)
    assert whole["symbolic"] == whole["geometric"]
    assert whole["geometric"]["kind"] == "learned"
    assert "policies/stack2" in whole["geometric"]["what"]
    skills = layers(load_scenario(LEARNING, "learned_tower5"), None)
    assert skills["symbolic"]["kind"] == "classical"
    assert skills["geometric"] == {
        "kind": "learned",
        "what": f"skills, {DESCRIBED} (package://cake_drake/policies/skills)",
        "shield": list(DEFAULT),
    }
    assert skills["dynamic"]["kind"] == "classical"


def test_the_shipped_learned_tower5_builds_the_tower(tmp_path):
    r = cli("cake_drake.run", "--scenario", str(LEARNING), "--name", "learned_tower5",
            "--out", str(tmp_path / "t5"))  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("goal reached: a on b on c on d on e")
    assert ("layers: symbolic classical (astar-lmcut) · geometric learned (skills, "
            f"{DESCRIBED} (package://cake_drake/policies/skills))") in r.stderr  # fmt: skip
    assert (SHIPPED / "README.md").is_file()
    size = sum(p.stat().st_size for p in SHIPPED.rglob("*") if p.is_file())
    assert size <= 10 * 2**20


def test_a_skill_reads_its_action_relative_to_the_hand_and_ends_where_the_classical_layer_does():
    from pydrake.math import RigidTransform, RotationMatrix

    from cake_drake.policy.observations import skill_context, skill_vector
    from cake_drake.symbolic import GroundAction
    from cake_drake.systems.skills import effects_hold
    from cake_drake.world.scene import SLOTS

    down = RotationMatrix.MakeXRotation(np.pi)
    cubes = {
        "a": RigidTransform([0.5, 0.1, 0.02]),
        "b": RigidTransform([0.5, -0.1, 0.02]),
        "z": RigidTransform([0.3, 0.3, 0.02]),  # a cube the action does not name
    }
    stack = GroundAction("stack", ("a", "b"))
    hand = RigidTransform(down, [0.5, 0.1, 0.2])
    ctx = skill_context(stack, cubes, SLOTS)
    v = skill_vector(ctx, cubes, hand)
    assert v[:4].tolist() == [0, 0, 0, 1]
    assert np.allclose(v[4:7], [0.0, 0.0, -0.18]) and np.allclose(v[8:11], [0.0, -0.2, -0.14])
    # The same numbers whatever other cubes there are, and however they are named.
    fewer = {k: X for k, X in cubes.items() if k != "z"}
    assert np.allclose(skill_vector(skill_context(stack, fewer, SLOTS), fewer, hand), v)
    # Placed, the hand open: done only once the hand is back up at the transit height.
    placed = {**cubes, "a": RigidTransform([0.5, -0.1, 0.06])}
    low = RigidTransform(down, [0.5, -0.1, 0.12])
    assert not effects_hold(ctx, placed, low, finger=0.04)
    high = RigidTransform(down, [0.5, -0.1, ctx.z_transit + 0.04])
    assert effects_hold(ctx, placed, high, finger=0.04)
    assert not effects_hold(ctx, cubes, high, finger=0.04)  # a is not on b
    # Picked: held in the closed hand at the transit height.
    pick = skill_context(GroundAction("pick-up", ("a",)), cubes, SLOTS)
    up = RigidTransform(down, [0.5, 0.1, pick.z_transit])
    lifted = {**cubes, "a": RigidTransform([0.5, 0.1, pick.z_transit])}
    assert effects_hold(pick, lifted, up, finger=0.019)
    assert not effects_hold(pick, lifted, up, finger=0.04)  # open: not held


def test_the_release_is_drawn_for_a_skill_that_decides_its_gripper(tmp_path):
    """``benchmarks/skills.py --release``: one held-out put-down of the shipped skill that
    never sees the arm, its gripper's decision drawn; a skill that decides no gripper (the
    joint-space one) is one line, exit 2."""

    def bench(*args):
        return subprocess.run([sys.executable, "benchmarks/skills.py", *args], cwd=ROOT,
                              capture_output=True, text=True, timeout=600,
                              env={**os.environ, "PYTHONPATH": str(ROOT)})  # fmt: skip

    png = tmp_path / "new" / "release.png"  # its folder made, as every output's
    r = bench("--release", str(png))
    assert r.returncode == 0, r.stderr
    assert f"{png}: " in r.stdout and "opened at" in r.stdout, r.stdout
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    r = bench("--release", str(tmp_path / "no.png"), "--skills", str(JOINT_SPACE))
    assert r.returncode == 2 and "decides no gripper" in r.stdout, r.stdout + r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "no.png").exists()
    r = bench("--release", str(tmp_path / "no.png"), "--skills", str(tmp_path / "none"))
    missing = "none: no such folder (a learned part"
    assert r.returncode == 2 and missing in r.stdout, r.stdout + r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "no.png").exists()
    r = bench("--release", str(tmp_path))  # onto a folder: refused before the episode
    assert r.returncode == 2 and "is a folder, not a regular file" in r.stdout, r.stdout
    r = bench("--release", str(tmp_path / "rl.png"), "--skills", str(SKILLS_RL))
    assert r.returncode == 0 and "opened at" in r.stdout, r.stdout + r.stderr  # its base's


SKILLS_RL = ROOT / "models" / "policies" / "skills_rl"
