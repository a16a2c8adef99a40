"""Learning from a reward: the reward's terms, Stable-Baselines3's PPO and SAC on the Gym
env (a few hundred steps), from scratch and as a residual on a frozen policy, and the
folder they write acting in evaluate, a run and the Gym env; bad recipes and damaged or
mismatched folders refused in one line.

Everything is real: Drake, the Gym env, Stable-Baselines3 and torch, the shipped policies.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from pydrake.math import RigidTransform

from cake_drake.errors import InputError
from cake_drake.learning.envs import rewards
from cake_drake.scenario import Reward
from cake_drake.world.facts import read_goal
from cake_drake.world.scene import CUBE_SIZE
from tests.helpers import ROOT

LEARNING = ROOT / "models" / "scenarios" / "learning.yaml"
ENV_ID = "cake_drake.gym:CakeDrake/Stack-v0"
STATE_BASE = ROOT / "models" / "policies" / "stack2"


def cake(command: str, *args: str, cwd: Path = ROOT, timeout: float = 900, env_extra=None):
    env = {**os.environ, "PYTHONPATH": str(ROOT), **(env_extra or {})}
    return subprocess.run(
        [sys.executable, "-m", f"cake_drake.{command}", *args],
        cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env,
    )  # fmt: skip


def short_folder() -> Path:
    """A new empty folder in /tmp, removed when the session ends: pytest's own are too
    deep for the sockets Ray makes in the temporary folder."""
    import atexit
    import shutil
    import tempfile

    folder = Path(tempfile.mkdtemp(prefix="t", dir="/tmp"))
    atexit.register(shutil.rmtree, folder, True)
    return folder


def one_line(r, code: int, *words: str) -> None:
    assert r.returncode == code, r.stdout + r.stderr
    assert "Traceback" not in r.stderr and r.stderr.count("\n") == 1, r.stderr
    for w in words:
        assert w in r.stderr, r.stderr


# --- the reward's terms -------------------------------------------------------------------


def _reading(positions: dict, hand=None, fingers=None):
    poses = {n: RigidTransform(np.asarray(p, float)) for n, p in positions.items()}
    goal = frozenset({("on", "a", "b"), ("on-table", "b")})
    X = None if hand is None else RigidTransform(np.asarray(hand, float))
    return read_goal(poses, goal, X, fingers), goal


def terms(positions: dict, start_z=None, hand=(0.5, 0.0, 0.3)) -> dict:
    progress, goal = _reading(positions)
    names = sorted(positions)
    p = np.array([positions[n] for n in names], float)
    z0 = p[:, 2].copy() if start_z is None else np.asarray(start_z, float)
    return rewards.terms(progress, goal, names, p, np.asarray(hand, float), z0)


H = CUBE_SIZE / 2


def test_the_place_term_pays_for_the_last_millimetres():
    # a on b, centred: the goal holds, every term at its best
    t = terms({"a": (0.5, 0.0, 3 * H), "b": (0.5, 0.0, H)})
    assert t["goal"] == 1.0 and t["success"] == 1.0 and t["place"] == pytest.approx(1.0)
    assert t["reach"] == t["lift"] == 1.0 and t["step"] == 1.0 and t["lost"] == 0.0
    # 5 mm off: the fact holds, the stack is loose (no success), half the place term
    t = terms({"a": (0.505, 0.0, 3 * H), "b": (0.5, 0.0, H)})
    assert t["goal"] == 1.0 and t["success"] == 0.0 and t["place"] == pytest.approx(0.5)
    # 12 mm off, or beside b: nothing for the place
    assert terms({"a": (0.512, 0.0, 3 * H), "b": (0.5, 0.0, H)})["place"] == 0.0
    assert terms({"a": (0.5, 0.2, H), "b": (0.5, 0.0, H)})["place"] == 0.0


def test_reach_and_lift_lead_to_the_cube_the_goal_moves():
    apart = {"a": (0.5, 0.2, H), "b": (0.5, 0.0, H)}
    far, near = terms(apart, hand=(0.5, 0.2, 0.5)), terms(apart, hand=(0.5, 0.2, H + 0.05))
    # 1 - tanh(d / 0.2): 0.5 m off earns little, 5 cm off most
    assert far["reach"] == pytest.approx(1 - np.tanh(2.5 - H / 0.2), abs=1e-9)
    assert near["reach"] == pytest.approx(1 - np.tanh(0.25)) and far["reach"] < 0.02
    lifted = terms({"a": (0.5, 0.2, H + 0.02), "b": (0.5, 0.0, H)}, start_z=(H, H))
    assert lifted["lift"] == pytest.approx(0.5) and lifted["goal"] == 0.5
    fallen = terms({"a": (0.5, 0.2, -0.3), "b": (0.5, 0.0, H)})
    assert fallen["lost"] == 1.0


def test_the_weights_sum_the_terms_and_default_to_the_goal_alone():
    # Every term a different power of two: a term dropped, counted twice or weighed by
    # another's weight changes the sum, and no two terms can cancel.
    values = {name: 2.0**k for k, name in enumerate(rewards.TERMS)}
    assert rewards.weighted(Reward(), values) == values["goal"]
    reward = rewards.check_reward({"place": 3.0, "step": -0.5})
    expected = values["goal"] + 3.0 * values["place"] - 0.5 * values["step"]
    assert reward.goal == 1.0 and rewards.weighted(reward, values) == pytest.approx(expected)
    every = rewards.check_reward({name: 1.0 for name in rewards.TERMS})
    assert rewards.weighted(every, values) == pytest.approx(sum(values.values()))


@pytest.mark.parametrize(
    ("weights", "words"),
    [
        ({"plce": 1.0}, "reward.plce: no such reward term; the terms: goal, success"),
        ({"place": "a lot"}, "reward.place = 'a lot': a weight is a finite number"),
        ({"place": float("nan")}, "a weight is a finite number"),
        ({"goal": 0.0}, "every weight is 0"),
        ([1, 2], "a mapping of term -> weight"),
    ],
)
def test_a_bad_reward_is_refused_when_the_env_is_made(weights, words):
    with pytest.raises(InputError, match=words.replace("(", r"\(").replace(")", r"\)")):
        gymnasium.make(ENV_ID, blocks=2, reward=weights)


def test_the_env_pays_the_weighted_terms_and_shows_each():
    env = gymnasium.make(ENV_ID, blocks=2, control_mode="joint_position",
                         reward={"goal": 1.0, "step": -2.0, "reach": 1.0})  # fmt: skip
    obs, _ = env.reset(seed=3)
    _, reward, *_, info = env.step(obs["state"][:8])
    t = info["reward_terms"]
    assert set(t) == set(rewards.TERMS)
    assert reward == pytest.approx(t["goal"] - 2.0 + t["reach"])


# --- recipes refused before anything runs --------------------------------------------------

TINY = """\
tiny:
  task: {{problem: "package://cake_drake/pddl/stack2.pddl"}}
  world: {{placement: {{xy: 0.02, yaw_deg: 20.0}}}}
  cameras: []
  reference: !Policy
    factory: "cake_drake.learning.expert:make"
    action_space: joint_position
    rate_hz: 10.0
    max_steps: 50
  training:
    rl:
      algorithm: ppo
      base: "{base}"
      steps: 128
      envs: 1
      rollout: 64
      batch_size: 32
      epochs: 1
      hidden_dims: [32, 32]
      residual_scale: 0.02
      reward: {{goal: 1.0, success: 20.0, place: 1.0, step: -2.0, lost: -100.0}}
"""


def suite(folder: Path, base: str = "", extra: str = "") -> Path:
    path = folder / "tiny.yaml"
    path.write_text(TINY.format(base=base) + extra)
    return path


@pytest.mark.parametrize(
    ("flags", "words"),
    [
        (["--steps", "0"], "training.rl.steps = 0: a whole number of environment steps, 1 to"),
        (["--algorithm", "sac", "--steps", "1000000000000"], "steps, 1 to 100,000,000"),
        (["--steps", "-5"], "training.rl.steps = -5"),
        (["--steps", "100"], "fewer than one rollout (512 steps x 2 environments = 1024)"),
        (["--algorithm", "dqn"], "training.rl.algorithm 'dqn'; choose one of: ppo, sac"),
        (["--base", "nowhere"], "nowhere: no such checkpoint folder"),
        (["--envs", "0"], "training.rl.envs = 0: a whole number from 1 to 64"),
    ],
)
def test_a_bad_budget_or_setting_is_refused_in_one_line(tmp_path, flags, words):
    r = cake("train", "--rl", str(LEARNING), "--name", "stack2", "--out", str(tmp_path / "o"),
             *flags)  # fmt: skip
    one_line(r, 2, words)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    ("reward", "words"),
    [
        ("{plce: 1.0}", "plce"),
        ("{place: lots}", "place"),
    ],
)
def test_a_bad_reward_in_a_recipe_is_refused_with_its_line(tmp_path, reward, words):
    text = TINY.format(base="").replace(
        "reward: {goal: 1.0, success: 20.0, place: 1.0, step: -2.0, lost: -100.0}",
        f"reward: {reward}",
    )
    (tmp_path / "tiny.yaml").write_text(text)
    r = cake("train", "--rl", "tiny.yaml", "--name", "tiny", "--out", "o", cwd=tmp_path)
    one_line(r, 2, "tiny.yaml", words)
    assert not (tmp_path / "o").exists()


def test_a_wall_clock_budget_stops_the_training_short_of_its_steps(tmp_path):
    text = TINY.format(base="").replace("steps: 128", "steps: 99968\n      minutes: 0.05")
    (tmp_path / "tiny.yaml").write_text(text)
    r = cake("train", "--rl", "tiny.yaml", "--name", "tiny", "--out", "o", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    info = json.loads((tmp_path / "o" / "rl.json").read_text())
    assert 1 <= info["steps"] < 99968 and info["recipe"]["minutes"] == 0.05, info["steps"]
    (tmp_path / "bad.yaml").write_text(text.replace("minutes: 0.05", "minutes: -1"))
    r = cake("train", "--rl", "bad.yaml", "--name", "tiny", "--out", "b", cwd=tmp_path)
    one_line(r, 2, "training.rl.minutes = -1.0: a number from 0.0 to 10000.0")
    assert not (tmp_path / "b").exists()


def test_rl_flags_without_rl_and_rl_with_a_dataset_are_refused(tmp_path):
    r = cake("train", str(tmp_path), "--out", str(tmp_path / "o"), "--base", "x")
    one_line(r, 2, "--base without --rl")
    r = cake("train", str(tmp_path), "--rl", str(LEARNING), "--name", "stack2", "--out",
             str(tmp_path / "o"))  # fmt: skip
    one_line(r, 2, "--rl reads no dataset")
    r = cake("train", "--rl", str(LEARNING), "--out", str(tmp_path / "o"))
    one_line(r, 2, "without --name")
    # a planned task with learned skills trains a skill residual: its base must be one
    r = cake("train", "--rl", str(LEARNING), "--name", "learned_tower5", "--out",
             str(tmp_path / "o"))  # fmt: skip
    base = "package://cake_drake/policies/stack2_pixels"
    one_line(r, 2, f"learned_tower5: training.rl.base {base}: a skill residual corrects")
    (tmp_path / "p.yaml").write_text(
        'plain:\n  task: {problem: "package://cake_drake/pddl/stack2.pddl"}\n'
    )
    r = cake("train", "--rl", str(tmp_path / "p.yaml"), "--name", "plain", "--out",
             str(tmp_path / "o"))  # fmt: skip
    one_line(r, 2, "plain: RL trains a task whose reference is a !Policy")


def test_without_stable_baselines3_rl_is_refused_with_the_line_that_installs_it(tmp_path):
    shadow = tmp_path / "shadow" / "stable_baselines3"
    shadow.mkdir(parents=True)
    (shadow / "__init__.py").write_text(
        "raise ModuleNotFoundError(\"No module named 'stable_baselines3'\", "
        "name='stable_baselines3')\n"
    )
    env = {**os.environ, "PYTHONPATH": f"{shadow.parent}{os.pathsep}{ROOT}"}
    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.train", "--rl", str(LEARNING), "--name", "stack2",
         "--out", str(tmp_path / "o")],
        cwd=ROOT, capture_output=True, text=True, timeout=300, env=env,
    )  # fmt: skip
    one_line(r, 2, "train --rl needs stable_baselines3, which is not installed: pip install")


# --- a few hundred steps, and the folder acting everywhere ----------------------------------


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> Path:
    """PPO for 128 steps: from scratch, and a residual on the shipped state policy."""
    folder = tmp_path_factory.mktemp("rl")
    for name, base in (("scratch", ""), ("residual", str(STATE_BASE))):
        (folder / name / "tmp").mkdir(parents=True)  # its TMPDIR: left empty (see below)
        r = cake("train", "--rl", str(suite(folder / name, base)), "--name", "tiny",
                 "--out", str(folder / name / "out"),
                 env_extra={"TMPDIR": str(folder / name / "tmp")})  # fmt: skip
        assert r.returncode == 0, r.stdout + r.stderr
        assert "128 steps" in r.stdout and "steps/s" in r.stdout, r.stdout
        (folder / name / "stdout.txt").write_text(r.stdout)
    return folder


def test_training_writes_the_model_its_description_and_a_learning_curve(trained):
    from PIL import Image

    for name in ("scratch", "residual"):
        out = trained / name / "out"
        assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == [
            "curve.png",
            "model.zip",
            "progress.csv",
            "rl.json",
        ]
        info = json.loads((out / "rl.json").read_text())
        assert info["steps"] == 128 and info["algorithm"] == "ppo"
        assert info["reward"]["success"] == 20.0 and info["reward"]["reach"] == 0.0
        rows = (out / "progress.csv").read_text().splitlines()
        # 50-step episodes: at least two
        assert rows[0] == "steps,return,length,success,wall_s" and len(rows) >= 3
        with Image.open(out / "curve.png") as im:
            assert im.size == (700, 520)
            pixels = np.asarray(im.convert("RGB"))
        green = (pixels[..., 1] > 120) & (pixels[..., 0] < 80) & (pixels[..., 2] < 80)
        assert green.sum() > 50  # the success line is drawn
        assert info["kind"] == name
    residual = json.loads((trained / "residual" / "out" / "rl.json").read_text())
    assert residual["kind"] == "residual" and residual["observation_size"] == 262 + 8
    for name in ("scratch", "residual"):  # a progress line a rollout, each printed once
        lines = (trained / name / "stdout.txt").read_text().splitlines()
        steps = [int(ln.split()[0]) for ln in lines if ln[:1].isdigit() and "steps/s" in ln]
        assert steps and steps[-1] == 128 and steps == sorted(set(steps)), lines
        # Nothing of the training's left in TMPDIR (Stable-Baselines3's own logger made
        # SB3-<date> there each time); torch keeps its compiler's cache there, for reuse.
        left = [p.name for p in (trained / name / "tmp").iterdir()]
        assert [n for n in left if not n.startswith("torchinductor_")] == [], left
    assert residual["base"]["path"] == "package://cake_drake/policies/stack2"


def test_a_trained_folder_acts_in_evaluate_a_run_and_the_gym_env(trained, tmp_path):
    out = trained / "residual" / "out"
    r = cake("evaluate", str(out), "--suite", str(LEARNING), "--name", "stack2", "--episodes",
             "1", "--seed", "1000", "--workers", "1", "--out", str(tmp_path / "ev"))  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "ev" / "summary.json").read_text())["episodes"] == 1
    (tmp_path / "s.yaml").write_text(
        'task: {problem: "package://cake_drake/pddl/stack2.pddl"}\n'
        f"reference: !Policy {{checkpoint: {out}, max_steps: 12}}\n"
        "outputs: {render: false}\n"
    )
    r = cake("run", "--scenario", "s.yaml", "--out", "run", cwd=tmp_path)
    assert r.returncode == 3 and "step budget of 12" in r.stderr, r.stderr
    layers = json.loads((tmp_path / "run" / "summary.json").read_text())["layers"]
    assert "imitation + RL residual, PPO" in layers["symbolic"]["what"]
    assert layers["symbolic"]["kind"] == "learned"
    from cake_drake.learning.policies.checkpoint import make

    env = gymnasium.make(ENV_ID, problem=str(ROOT / "models/pddl/stack2.pddl"),
                         control_mode="joint_position")  # fmt: skip
    policy = make(str(trained / "scratch" / "out"))
    obs, _ = env.reset(seed=2)
    policy.reset(env.unwrapped.policy_task, 2)
    for _ in range(3):
        action = policy.act(obs)
        assert action.shape == (8,) and np.all(np.isfinite(action))
        obs, *_ = env.step(action)


def _side_by_side(folder: Path, steps: int, edit) -> list[tuple[np.ndarray, np.ndarray]]:
    """(base action, residual policy's action) at each step of one episode, the learner's
    last layer set by ``edit``; the base's within the action space's bounds, as the slot
    would execute it."""
    import torch

    from cake_drake.learning.policies.lerobot_checkpoint import CheckpointPolicy
    from cake_drake.learning.policies.rl import RlPolicy

    env = gymnasium.make(ENV_ID, problem=str(ROOT / "models/pddl/stack2.pddl"),
                         control_mode="joint_position")  # fmt: skip
    obs, _ = env.reset(seed=5)
    task = env.unwrapped.policy_task
    policy, base = RlPolicy(str(folder)), CheckpointPolicy(str(STATE_BASE), "cpu")
    policy.reset(task, 5)
    base.reset(task, 5)
    with torch.no_grad():
        edit(policy._model.policy.action_net)
    from cake_drake.geometric.ik import Kinematics
    from cake_drake.policy import spaces

    kin = Kinematics()
    low, high = spaces.bounds("joint_position", {}, kin.lower, kin.upper)
    pairs = []
    for _ in range(steps):
        a, b = policy.act(obs), base.act(obs)
        pairs.append((np.clip(b, low, high), a))  # the slot clips either to the space
        obs, *_ = env.step(a)
    return pairs


def test_a_residual_with_zero_weights_changes_nothing_and_is_bounded(trained):
    out = trained / "residual" / "out"

    def zero(layer):
        layer.weight.zero_()
        layer.bias.zero_()

    for base, action in _side_by_side(out, 12, zero):
        np.testing.assert_array_equal(action, base)

    def large(layer):
        layer.weight.zero_()
        layer.bias.fill_(50.0)  # far past the bound

    moved = 0
    for base, action in _side_by_side(out, 12, large):
        diff = action[:7] - base[:7]
        assert np.all(np.abs(diff) <= 0.02 + 1e-9)
        moved += int(np.any(np.abs(diff) > 0.019))
        assert action[7] == base[7]  # the gripper's bound is 0: the base's own
    assert moved >= 6  # the bound is reached, not just respected


def test_on_local_ray_two_runners_write_the_same_files(trained, tmp_path):
    pytest.importorskip("ray")
    text = TINY.format(base="").replace("envs: 1", "envs: 2").replace("steps: 128", "steps: 256")
    (tmp_path / "tiny.yaml").write_text(text)
    temporary = short_folder()  # short enough for Ray's sockets
    r = cake("train", "--rl", "tiny.yaml", "--name", "tiny", "--out", "o", "--ray", cwd=tmp_path,
             env_extra={"TMPDIR": str(temporary)})  # fmt: skip
    assert r.returncode == 0, r.stdout + r.stderr
    assert not list(temporary.glob("*ray*")), "Ray's session folder was left"
    out, alone = tmp_path / "o", trained / "scratch" / "out"
    assert sorted(p.name for p in out.iterdir()) == sorted(p.name for p in alone.iterdir())
    info = json.loads((out / "rl.json").read_text())
    other = json.loads((alone / "rl.json").read_text())
    assert info["runners"] == "2 on local Ray instance"
    assert other["runners"] == "1 on this machine"
    assert set(info) == set(other) and info["reward"] == other["reward"]
    # two 50-step episodes' worth on each runner, every one of them reported once
    assert info["steps"] == 256 and info["episodes"] >= 4
    rows = (out / "progress.csv").read_text().splitlines()
    assert rows[0] == "steps,return,length,success,wall_s" and len(rows) == info["episodes"] + 1
    assert all(int(row.split(",")[2]) == 50 for row in rows[1:])  # episodes end at the budget


@pytest.mark.slow
def test_on_local_ray_sigterm_is_one_line_and_leaves_no_session_folder(tmp_path):
    """Ray puts a crash dump and an abort 3 s later on SIGTERM: the command's own stop."""
    import signal
    import time

    pytest.importorskip("ray")
    text = TINY.format(base="").replace("envs: 1", "envs: 2").replace("steps: 128", "steps: 99999")
    (tmp_path / "tiny.yaml").write_text(text)
    temporary = short_folder()
    proc = subprocess.Popen(
        [sys.executable, "-m", "cake_drake.train", "--rl", "tiny.yaml", "--name", "tiny",
         "--out", "o", "--ray"],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT), "TMPDIR": str(temporary)},
    )  # fmt: skip
    deadline = time.monotonic() + 300
    while not list((tmp_path / "o").glob(".staging-*")) and proc.poll() is None:
        assert time.monotonic() < deadline, "the training never began"
        time.sleep(0.2)
    time.sleep(8)  # Ray's runners are up and stepping
    assert proc.poll() is None, proc.communicate()
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert err == "error: interrupted by SIGTERM; nothing was written\n", err
    assert not (tmp_path / "o").exists()
    assert not list(temporary.glob("*ray*")), "Ray's session folder was left"


@pytest.mark.parametrize("delay", [0.3, 1.5])
def test_sigterm_while_local_ray_starts_is_the_command_s_stop(delay):
    """While ``ray.init`` runs, Ray's own handlers meet a SIGTERM (exit 15, or an abort
    3 s on): the command still ends as stopped by SIGTERM, its session folder gone."""
    pytest.importorskip("ray")
    script = (
        "import os, signal, sys, threading, time\n"
        "from cake_drake.errors import run_cli\n"
        "from cake_drake.sweeps import RayCluster\n"
        "def main(argv):\n"
        "    c = RayCluster(None, 1)\n"
        f"    threading.Timer({delay}, os.kill, (os.getpid(), signal.SIGTERM)).start()\n"
        "    try:\n"
        "        c.start()\n"
        "        time.sleep(30)\n"
        "    finally:\n"
        "        c.stop()\n"
        "    return 0\n"
        "raise SystemExit(run_cli(main, []))\n"
    )
    temporary = short_folder()
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                       timeout=120, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT),
                                                   "TMPDIR": str(temporary)})  # fmt: skip
    assert r.returncode == 130, r.stderr
    assert r.stderr.splitlines()[-1] == "error: interrupted by SIGTERM; nothing was written"
    assert not list(temporary.glob("*ray*")), "Ray's session folder was left"


def test_a_ray_address_nothing_answers_at_is_refused_before_training(tmp_path):
    pytest.importorskip("ray")
    r = cake("train", "--rl", str(suite(tmp_path)), "--name", "tiny", "--out",
             str(tmp_path / "o"), "--ray", "127.0.0.1:1", timeout=60)  # fmt: skip
    one_line(r, 2, "--ray 127.0.0.1:1: no Ray cluster answers there")
    assert not (tmp_path / "o").exists()
    r = cake("train", "--planner", "--out", str(tmp_path / "p"), "--ray")
    one_line(r, 2, "--ray")


def test_sac_trains_too(tmp_path):
    path = suite(tmp_path)
    r = cake("train", "--rl", str(path), "--name", "tiny", "--algorithm", "sac", "--steps",
             "96", "--out", str(tmp_path / "sac"))  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "RL from scratch (SAC)" in r.stdout
    assert json.loads((tmp_path / "sac" / "rl.json").read_text())["algorithm"] == "sac"


# --- folders that do not fit, or are damaged ------------------------------------------------


def _copy(trained: Path, tmp_path: Path) -> Path:
    copy = tmp_path / "copy"
    shutil.copytree(trained / "residual" / "out", copy)
    return copy


def _replace_member(archive: Path, member: str, data: bytes) -> None:
    import zipfile

    with zipfile.ZipFile(archive) as z:
        members = {n: z.read(n) for n in z.namelist()}
    members[member] = data
    with zipfile.ZipFile(archive, "w") as z:
        for n, d in members.items():
            z.writestr(n, d)


def _nan_policy(archive: Path) -> bytes:
    """The archive's policy.pth with its first tensor made NaN (readable, not numbers)."""
    import io
    import zipfile

    import torch

    with zipfile.ZipFile(archive) as z:
        state = torch.load(io.BytesIO(z.read("policy.pth")), weights_only=True)
    first = next(iter(state))
    state[first] = torch.full_like(state[first], float("nan"))
    out = io.BytesIO()
    torch.save(state, out)
    return out.getvalue()


def evaluate(folder: Path, tmp_path: Path, name: str = "stack2"):
    return cake("evaluate", str(folder), "--suite", str(LEARNING), "--name", name,
                "--episodes", "1", "--workers", "1", "--out", str(tmp_path / "ev"))  # fmt: skip


def test_a_residual_for_another_base_is_refused(trained, tmp_path):
    copy = _copy(trained, tmp_path)
    info = json.loads((copy / "rl.json").read_text())
    info["base"]["sha256"] = "0" * 64
    (copy / "rl.json").write_text(json.dumps(info))
    one_line(evaluate(copy, tmp_path), 2, "a residual for another base policy")
    info["base"]["path"] = "package://cake_drake/policies/stack2_pixels"
    (copy / "rl.json").write_text(json.dumps(info))
    r = evaluate(copy, tmp_path)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert not (tmp_path / "ev").exists()


def test_a_residual_for_another_action_space_is_refused(trained, tmp_path):
    from cake_drake.learning.policies.checkpoint import check_folder

    said = "learned in joint_position; the run's action space is ee_delta"
    with pytest.raises(InputError, match=said):
        check_folder(trained / "residual" / "out", "ee_delta")
    (tmp_path / "s.yaml").write_text(
        'task: {problem: "package://cake_drake/pddl/stack2.pddl"}\n'
        f"reference: !Policy {{checkpoint: {trained / 'residual' / 'out'}, "
        "action_space: ee_delta}\noutputs: {render: false}\n"
    )
    r = cake("run", "--scenario", "s.yaml", "--out", "run", cwd=tmp_path)
    one_line(r, 2, "learned in joint_position")
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    ("damage", "words"),
    [
        (lambda f: (f / "rl.json").write_text('{"format": 1, "kind": "re'), "rl.json: unreadable"),
        (lambda f: (f / "rl.json").write_text("[1, 2]"), "not a mapping"),
        (lambda f: (f / "model.zip").write_bytes(b"PK\x03\x04 no"), "model.zip: not a readable"),
        (lambda f: (f / "model.zip").unlink(), "model.zip: not a readable"),
        (
            lambda f: _replace_member(f / "model.zip", "policy.pth", b"garbage" * 100),
            "model.zip: its weights cannot be read",
        ),
        (
            lambda f: _replace_member(f / "model.zip", "policy.pth", _nan_policy(f / "model.zip")),
            "holds NaN or infinite values",
        ),
        (
            lambda f: (f / "rl.json").write_text(
                (f / "rl.json").read_text().replace('"action_size": 8', '"action_size": 7')
            ),
            "does not fit a residual over 7 actions",
        ),
        (
            lambda f: (f / "rl.json").write_text(
                (f / "rl.json").read_text().replace('"kind": "residual"', '"kind": "magic"')
            ),
            "field 'kind' is 'magic', not valid",
        ),
    ],
)
def test_a_damaged_rl_folder_is_one_line_before_any_episode(trained, tmp_path, damage, words):
    copy = _copy(trained, tmp_path)
    damage(copy)
    one_line(evaluate(copy, tmp_path), 2, words)
    assert not (tmp_path / "ev").exists()


# --- the residual that ships --------------------------------------------------------------


@pytest.mark.slow
def test_the_shipped_residual_names_its_base_and_runs_its_scenario(tmp_path):
    """models/policies/stack2_pixels_rl: the pixel policy's residual, checked against its
    base's weights, runs its scenario and says what it is. How it compares with its base
    is a 50-seed table (docs/learning.md: 15/50 against 20/50), not any one seed."""
    from cake_drake.learning.policies.lerobot_checkpoint import model_folder
    from cake_drake.learning.policies.rl import digest, read_rl

    shipped = ROOT / "models" / "policies" / "stack2_pixels_rl"
    info = read_rl(shipped)
    assert info["kind"] == "residual" and info["residual_scale"] == 0.02
    assert info["base"]["path"] == "package://cake_drake/policies/stack2_pixels"
    base = model_folder(ROOT / "models" / "policies" / "stack2_pixels")
    assert info["base"]["sha256"] == digest(base)
    assert sum(f.stat().st_size for f in shipped.iterdir()) < 5_000_000
    r = cake("run", "--scenario", str(LEARNING), "--name", "learned_stack2_pixels_rl",
             "--no-render", "--out", str(tmp_path / "rl"))  # fmt: skip
    # The scenario's seed is one it stacks, as its comment says: the same every time.
    assert r.returncode == 0 and "goal reached: a on b" in r.stdout + r.stderr, r.stderr
    layers = json.loads((tmp_path / "rl" / "summary.json").read_text())["layers"]
    assert "imitation + RL residual, PPO" in layers["geometric"]["what"]


@pytest.mark.slow
def test_sigterm_to_a_training_on_two_environments_ends_it_in_one_line(tmp_path):
    """A scheduler's stop (SIGTERM to the command alone): exit 130 at once, OUT never made,
    the environments' processes gone. (An interrupt between two environments' answers to a
    step once left Stable-Baselines3's close() waiting on a pipe forever.)"""
    import signal
    import time

    text = TINY.format(base="").replace("envs: 1", "envs: 2").replace("steps: 128", "steps: 100000")
    (tmp_path / "tiny.yaml").write_text(text)
    proc = subprocess.Popen(
        [sys.executable, "-m", "cake_drake.train", "--rl", "tiny.yaml", "--name", "tiny",
         "--out", "o"],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)}, start_new_session=True,
    )  # fmt: skip
    deadline = time.monotonic() + 300
    line = proc.stdout.readline()  # the first progress line: the environments are stepping
    assert "steps/s" in line or time.monotonic() > deadline, line
    os.kill(proc.pid, signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and err.count("\n") == 1, err
    assert not (tmp_path / "o").exists()
    gone = time.monotonic() + 30
    while time.monotonic() < gone:
        try:
            os.killpg(proc.pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.1)
    else:
        os.killpg(proc.pid, signal.SIGKILL)
        pytest.fail("the environments' processes were left running")
