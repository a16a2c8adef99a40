"""The classical cake as a teacher of a learned policy: noise-injected demonstrations (DART,
``record --noise``) and DAgger (``train --dagger``).

Everything is real: Drake, the closed-loop expert, lerobot's writer, loader and trainer (a
few steps), torch.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import gymnasium
import numpy as np
import pytest

from cake_drake.learning.rollout import EXPERT as CLOSED_LOOP
from cake_drake.learning.rollout import NOISE_MAX, EpisodeSpec, noise_scale, rollout
from tests.helpers import ROOT

LEARNING = ROOT / "models" / "scenarios" / "learning.yaml"
STACK2 = str(ROOT / "models" / "pddl" / "stack2.pddl")
EXPERT = "examples.expert_policy:make"
SIGMA = 0.005  # rad a joint: small enough that the expert builds stack2 from seeds 0 and 1


def cake(command: str, *args: str, timeout: float = 900):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run(
        [sys.executable, "-m", f"cake_drake.{command}", *args],
        cwd=ROOT, capture_output=True, text=True, timeout=timeout, env=env,
    )  # fmt: skip


def one_line(r, code: int, *words: str) -> None:
    assert r.returncode == code, r.stderr
    assert "Traceback" not in r.stderr and r.stderr.count("\n") == 1, r.stderr
    for w in words:
        assert w in r.stderr, r.stderr


def record(out: Path, *flags: str, episodes: int = 2):
    r = cake("record", str(LEARNING), "--name", "stack2", "--out", str(out), "--episodes",
             str(episodes), "--workers", "1", "--no-cameras", *flags)  # fmt: skip
    assert r.returncode == 0, r.stderr
    return json.loads((out / "report.json").read_text())


def parquet_bytes(root: Path) -> bytes:
    return b"".join(p.read_bytes() for p in sorted((root / "data").rglob("*.parquet")))


# --- DART: the executed action noised, the recorded one the expert's ------------------------


def test_noise_units_and_bounds_per_action_space():
    assert np.array_equal(noise_scale("joint_position"), [1, 1, 1, 1, 1, 1, 1, 0])
    assert np.allclose(noise_scale("ee_delta"), [1, 1, 1, 5, 5, 5, 0])  # 0.25 rad per 0.05 m
    assert NOISE_MAX == {"joint_position": 0.1, "ee_delta": 0.05}


@pytest.mark.slow
def test_a_noisy_episode_records_the_experts_clean_answer_at_every_state_it_visits():
    from cake_drake.geometric.ik import Kinematics
    from cake_drake.systems.policy_source import make_policy

    spec = EpisodeSpec(problem=STACK2, max_steps=60, policy=EXPERT, noise=SIGMA)
    ep = rollout(spec, 1)
    again = rollout(spec, 1)
    assert np.array_equal(ep.executed, again.executed)  # the same seed, the same noise
    assert np.all(ep.actors == 0)
    joints = np.abs(ep.executed[:, :7] - ep.actions[:, :7])
    assert np.all(joints > 0) and np.all(joints < 5 * SIGMA)  # noised, and by about SIGMA
    assert np.array_equal(ep.executed[:, 7], ep.actions[:, 7])  # the gripper is not
    # The labels are what the expert answers on the states the noisy actions led to.
    env = spec.env()
    obs, _ = env.reset(seed=1)
    expert = make_policy(EXPERT, {})
    expert.reset(env.unwrapped.policy_task, 1)
    kin = Kinematics()
    for k in range(len(ep.actions)):
        answer = np.clip(expert.act(obs), np.r_[kin.lower, 0.0], np.r_[kin.upper, 0.08])
        assert np.array_equal(answer.astype(np.float32), ep.actions[k]), k
        obs, *_ = env.step(ep.executed[k])
    clean = rollout(EpisodeSpec(problem=STACK2, max_steps=60, policy=EXPERT), 1)
    assert not np.array_equal(clean.states, ep.states)  # the noise moved the arm


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """stack2 on seeds 0 and 1: plainly, with --noise 0, and twice with --noise SIGMA."""
    folder = tmp_path_factory.mktemp("dart")
    reports = {name: record(folder / name, *flags) for name, flags in (
        ("plain", ()), ("zero", ("--noise", "0")),
        ("noisy", ("--noise", str(SIGMA))), ("again", ("--noise", str(SIGMA))),
    )}  # fmt: skip
    return folder, reports


@pytest.mark.slow
def test_a_noisy_recording_is_seeded_measured_and_a_dataset_lerobot_loads(recordings):
    from cake_drake.learning.data.dataset import read

    folder, reports = recordings
    noisy = reports["noisy"]
    assert noisy["noise"] == SIGMA and noisy["spec"]["noise"] == SIGMA
    assert noisy["episodes"] >= 1 and noisy["episodes"] + len(noisy["failed"]) == 2
    assert parquet_bytes(folder / "noisy") == parquet_bytes(folder / "again")
    assert parquet_bytes(folder / "noisy") != parquet_bytes(folder / "plain")
    data = read(folder / "noisy")
    assert data.num_frames == noisy["frames"] and int(data[0]["actor"]) == 0
    seed = noisy["seeds"][0]
    with np.load(folder / "noisy" / "episodes" / f"ep_{seed}.npz") as z:
        assert not np.array_equal(z["executed"], z["actions"])
        assert np.array_equal(data.hf_dataset.with_format("numpy")["action"][: len(z["actions"])],
                              z["actions"])  # fmt: skip
    # Success is measured from the poses: what ran rebuilds every kept goal.
    r = cake("record", "--replay", str(folder / "noisy"), "--workers", "1")
    assert r.returncode == 0, r.stderr
    assert f"{noisy['episodes']}/{noisy['episodes']} episodes rebuild the goal" in r.stdout


@pytest.mark.slow
def test_zero_noise_records_what_a_plain_recording_does(recordings):
    folder, reports = recordings
    assert reports["zero"]["noise"] == 0.0 and reports["plain"]["noise"] == 0.0
    assert parquet_bytes(folder / "zero") == parquet_bytes(folder / "plain")


@pytest.mark.slow
def test_resume_with_another_noise_is_refused(recordings, tmp_path):
    import shutil

    folder, _ = recordings
    shutil.copytree(folder / "noisy", tmp_path / "ds")
    r = cake("record", str(LEARNING), "--name", "stack2", "--out", str(tmp_path / "ds"),
             "--episodes", "2", "--no-cameras", "--resume", "--noise", "0.01")  # fmt: skip
    one_line(r, 2, "--resume with another noise", "0.005", "0.01")


def test_resume_with_another_load_is_refused(recordings, tmp_path):
    """The cubes' mass range is part of what a recording is: resuming one with another
    would mix two worlds in one dataset."""
    import shutil

    folder, _ = recordings
    shutil.copytree(folder / "noisy", tmp_path / "ds")
    heavy = tmp_path / "heavy.yaml"
    heavy.write_text(
        "stack2:\n"
        '  task: {problem: "package://cake_drake/pddl/stack2.pddl"}\n'
        "  world: {placement: {xy: 0.025, yaw_deg: 30.0}, cube_mass_range_kg: [0.1, 0.2]}\n"
        '  reference: !Policy {factory: "cake_drake.learning.expert:make", '
        "action_space: joint_position, rate_hz: 10.0, max_steps: 400}\n"
    )
    r = cake("record", str(heavy), "--name", "stack2", "--out", str(tmp_path / "ds"),
             "--episodes", "2", "--no-cameras", "--resume", "--noise", "0.005")  # fmt: skip
    one_line(r, 2, "--resume with another cube_mass_range_kg", "[0.1, 0.2]")


@pytest.mark.parametrize(
    "value, words",
    [
        ("-0.01", ["--noise -0.01", "from 0 to 0.1"]),
        ("nan", ["--noise nan", "from 0 to 0.1"]),
        ("0.2", ["--noise 0.2", "from 0 to 0.1 (rad on each joint) for joint_position"]),
    ],
)
def test_bad_noise_is_one_line(tmp_path, value, words):
    r = cake("record", str(LEARNING), "--name", "stack2", "--out", str(tmp_path / "ds"),
             "--episodes", "1", "--no-cameras", f"--noise={value}")  # fmt: skip
    one_line(r, 2, *words)
    assert not (tmp_path / "ds").exists()


# --- DAgger -------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def dagger_run(recordings):
    folder, _ = recordings
    out = folder / "dagger"
    r = cake("train", str(folder / "plain"), "--out", str(out), "--steps", "2", "--batch-size",
             "4", "--device", "cpu", "--dagger", "1", "--episodes-per-round", "1", "--beta",
             "0.5", "--workers", "1")  # fmt: skip
    assert r.returncode == 0, r.stderr
    return folder, out, r.stdout


def test_the_expert_gives_up_after_its_repairs_unless_unbounded():
    from cake_drake.learning.policies.expert import MAX_REPAIRS, ClosedLoopExpert

    bounded, unbounded = ClosedLoopExpert(), ClosedLoopExpert(max_repairs=None)
    for expert in (bounded, unbounded):
        expert.repairs = 0  # as reset() leaves it
    assert [bounded._repair("drop", "off", k) for k in range(MAX_REPAIRS + 1)] == [True] * (
        MAX_REPAIRS) + [False]  # fmt: skip
    assert bounded.reason.startswith(f"gave up after {MAX_REPAIRS} repairs; the last: off")
    assert all(unbounded._repair("drop", "off", k) for k in range(10 * MAX_REPAIRS))
    assert unbounded.reason is None


def test_the_classical_teacher_is_unbounded_unless_its_options_bound_it():
    from dataclasses import replace

    from cake_drake.learning.rollout import EpisodeSpec
    from cake_drake.learning.training.dagger import labeller

    spec = EpisodeSpec(policy=CLOSED_LOOP, options={"slow": 0.5})
    assert labeller(spec, 0.3).options == {"slow": 0.5, "max_repairs": None}
    bounded = replace(spec, options={"max_repairs": 5})
    assert labeller(bounded, 0.3).options == {"max_repairs": 5}
    mine = replace(spec, policy="examples.random_policy:make", options={})
    assert labeller(mine, 0.3).options == {}
    assert spec.options == {"slow": 0.5}  # the recording's spec is not changed


@pytest.mark.slow
def test_a_dagger_round_labels_the_learners_states_and_fine_tunes(dagger_run):
    from cake_drake.learning.data.dataset import read
    from cake_drake.learning.policies.checkpoint import make

    folder, out, stdout = dagger_run
    plain = json.loads((folder / "plain" / "report.json").read_text())
    lines = stdout.splitlines()
    assert lines[0].startswith("round 0: mlp trained 2 steps on 2 demonstrations")
    made = json.loads((out / "train.json").read_text())
    summary = made["dagger"]
    (row,) = summary["rounds"]
    # Where its time went: the rollouts, the datasets written, and both trainings' phases.
    phases = made["phases_s"]
    assert phases["rollouts"] > 0 and phases["writing"] > 0 and phases["network"] > 0
    rounds = [json.loads((out / "rounds" / f"round-{k}" / "train.json").read_text())
              for k in (0, 1)]  # fmt: skip
    assert phases["train"] == pytest.approx(sum(r["phases_s"]["train"] for r in rounds), abs=2e-3)
    added, by_learner = row["frames_added"], row["learner_frames"]
    assert 0 < by_learner < added  # both acted (beta 0.5)
    assert row["expert_labelled_frames"] == plain["frames"] + added
    assert lines[1].startswith(
        f"round 1: 1 episodes, {added} frames added ({by_learner} by the learner, "
        f"{added - by_learner} by the expert), {plain['frames'] + added} expert-labelled "
        "frames in all; the learner's rollouts reached the goal in "
    )
    first = max(plain["seeds"] + [f["seed"] for f in plain["failed"]]) + 1
    assert row["seeds"] == [first]  # not a demonstration's seed
    # The aggregated dataset: the demonstrations, then the round's episode, who acted kept.
    data = read(out / "data" / "round-1")
    table = data.hf_dataset.with_format("numpy")
    actors = np.asarray(table["actor"]).ravel()
    assert data.num_episodes == plain["episodes"] + 1 and len(actors) == plain["frames"] + added
    assert not actors[: plain["frames"]].any() and actors[plain["frames"] :].sum() == by_learner
    # The classical teacher never gives up on a learner's states: its repairs are unbounded.
    assert summary["teacher"] == {"policy": CLOSED_LOOP, "options": {"max_repairs": None}}
    rollout = json.loads((out / "rollouts" / f"ep_{first}.json").read_text())
    assert "gave up" not in rollout["reason"], rollout
    with np.load(out / "rollouts" / f"ep_{first}.npz") as z:
        expert_acted = z["actors"] == 0
        assert np.array_equal(z["executed"][expert_acted], z["actions"][expert_acted])
        assert not np.array_equal(z["executed"][~expert_acted], z["actions"][~expert_acted])
        assert np.array_equal(np.asarray(table["action"])[plain["frames"] :], z["actions"])
    # Fine-tuned from round 0, and the checkpoint in the usual place acts.
    model = out / "checkpoints" / "last" / "pretrained_model"
    config = json.loads((model / "config.json").read_text())
    assert Path(config["pretrained_path"]).parts[-5:-3] == ("rounds", "round-0")
    base = out / "rounds" / "round-0" / "checkpoints" / "last" / "pretrained_model"
    assert (model / "model.safetensors").read_bytes() != (base / "model.safetensors").read_bytes()
    policy = make(str(out), "cpu")
    env = gymnasium.make(
        "cake_drake.gym:CakeDrake/Stack-v0", problem=STACK2, control_mode="joint_position"
    )
    obs, _ = env.reset(seed=5)
    policy.reset(env.unwrapped.policy_task, 5)
    action = policy.act(obs)
    assert action.shape == (8,) and np.all(np.isfinite(action))


@pytest.mark.slow
@pytest.mark.parametrize(
    "flags, words",
    [
        (["--dagger", "0"], ["--dagger 0: rounds of DAgger, from 1 to 1000"]),
        (["--dagger", "-2"], ["--dagger -2"]),
        (["--dagger", "1", "--beta", "1.5"], ["--beta 1.5", "from 0 to 1"]),
        (["--dagger", "1", "--beta", "nan"], ["--beta nan"]),
        (["--dagger", "1", "--episodes-per-round", "0"], ["--episodes-per-round 0"]),
        (["--beta", "0.5"], ["--beta without --dagger"]),
        (["--dagger", "1", "--resume"], ["--resume with --dagger"]),
    ],
)
def test_bad_dagger_settings_are_one_line(recordings, tmp_path, flags, words):
    folder, _ = recordings
    r = cake("train", str(folder / "plain"), "--out", str(tmp_path / "run"), *flags)
    one_line(r, 2, *words)
    assert not (tmp_path / "run").exists()


@pytest.mark.slow
def test_dagger_on_a_dataset_with_no_task_or_no_episodes_is_one_line(recordings, tmp_path):
    import shutil

    folder, _ = recordings
    bare = tmp_path / "bare"  # a LeRobot dataset, but no report.json: no task to roll out on
    shutil.copytree(folder / "plain", bare, ignore=shutil.ignore_patterns("report.json"))
    r = cake("train", str(bare), "--out", str(tmp_path / "run"), "--dagger", "1")
    one_line(r, 2, "report.json: missing", "--dagger rolls the policy out")
    lost = tmp_path / "lost"  # a task, but its episodes are gone: nothing to append to
    shutil.copytree(folder / "plain", lost, ignore=shutil.ignore_patterns("episodes"))
    r = cake("train", str(lost), "--out", str(tmp_path / "run"), "--dagger", "1")
    one_line(r, 2, "ep_0.npz: missing", "--dagger appends to the recording's kept episodes")
    assert not (tmp_path / "run").exists()


@pytest.mark.slow
def test_a_damaged_kept_episode_is_one_line_before_anything_trains(recordings, tmp_path):
    import shutil

    folder, reports = recordings
    damaged = tmp_path / "damaged"
    shutil.copytree(folder / "plain", damaged)
    kept = damaged / "episodes" / f"ep_{reports['plain']['seeds'][0]}.npz"
    kept.write_bytes(kept.read_bytes()[: kept.stat().st_size // 2])  # cut short
    r = cake("train", str(damaged), "--out", str(tmp_path / "run"), "--steps", "2",
             "--device", "cpu", "--dagger", "1", "--workers", "1")  # fmt: skip
    one_line(r, 2, str(kept))
    assert not (tmp_path / "run").exists()
    shaped = tmp_path / "shaped"  # readable, but an array of the wrong shape
    shutil.copytree(folder / "plain", shaped)
    kept = shaped / "episodes" / kept.name
    with np.load(kept) as z:
        arrays = dict(z)
    np.savez(kept, **{**arrays, "environment": arrays["environment"][:-1]})
    r = cake("train", str(shaped), "--out", str(tmp_path / "run"), "--steps", "2",
             "--device", "cpu", "--dagger", "1", "--workers", "1")  # fmt: skip
    one_line(r, 2, str(kept), "disagree on the number of samples")
    assert not (tmp_path / "run").exists()


@pytest.mark.slow
def test_dagger_stopped_in_round_0_leaves_its_folder_as_it_was(recordings, tmp_path):
    import signal
    import time

    folder, _ = recordings
    out = tmp_path / "run"
    out.mkdir()
    (out / "mine.txt").write_text("the user's\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "cake_drake.train", str(folder / "plain"), "--out", str(out),
         "--steps", "100000", "--batch-size", "4", "--device", "cpu", "--dagger", "1",
         "--workers", "1"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip
    deadline = time.monotonic() + 300
    # Its folders are made in the staging folder just before round 0 trains.
    while not list(out.glob(".staging-*/rollouts")) and proc.poll() is None:
        assert time.monotonic() < deadline, "round 0 never started"
        time.sleep(0.2)
    time.sleep(3)  # into round 0's training
    assert proc.poll() is None, proc.communicate()
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert sorted(p.name for p in out.iterdir()) == ["mine.txt"], list(out.iterdir())
