"""The learned layer's slot: a policy drives the same Diagram, and Gymnasium drives a policy.

Everything runs for real: Drake, the renderer, gymnasium's own checker and vector env.
The expert (the classical cake as a policy) must build the tower through every action
space; the random policy must not.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import gymnasium
import numpy as np
import pytest

from cake_drake.errors import InputError
from cake_drake.pipeline import check, run
from cake_drake.scenario import Policy, Scenario, parse_scenario
from cake_drake.symbolic import PROBLEM_5
from tests.helpers import ROOT

ENV_ID = "cake_drake.gym:CakeDrake/Stack-v0"
sys.path.insert(0, str(ROOT))  # examples/


def policy_scenario(space: str, factory: str = "examples.expert_policy:make", **options):
    s = Scenario(reference=Policy(factory=factory, action_space=space, options=options))
    s.outputs.render = False
    return s


@pytest.mark.slow
@pytest.mark.parametrize(
    "space, options",
    [("joint_position", {}), ("ee_delta", {}), ("joint_chunk", {"horizon": 10, "execute": 5})],
)
def test_the_expert_builds_the_tower_in_every_action_space(space, options):
    result = run(policy_scenario(space, **options), write=False)
    assert result.success, result.message
    source = result.cake.reference.policy
    assert source.done and source.counts.unreachable == 0


def test_the_random_policy_does_not_build_the_tower():
    s = policy_scenario("ee_delta", "examples.random_policy:make")
    s.reference.max_steps = 40
    result = run(s, write=False)
    assert not result.success and "(on c d)" in result.message
    assert result.cake.reference.policy.steps == 40


def test_a_policy_run_leaves_controller_loggers_and_verdict_as_they_are(tmp_path):
    (tmp_path / "s.yaml").write_text(
        "reference: !Policy {factory: examples.expert_policy:make, action_space: joint_position}\n"
        "outputs: {render: false}\n"
    )
    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.run", "--scenario", str(tmp_path / "s.yaml"),
         "--out", str(tmp_path / "o"), "--quiet"],
        capture_output=True, text=True, timeout=300, cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "goal reached: a on b on c on d on e" in r.stdout
    for name in ("summary.json", "trajectory.npz", "joint4_torque.png", "scenario.yaml"):
        assert (tmp_path / "o" / name).is_file()
    assert "!Policy" in (tmp_path / "o" / "scenario.yaml").read_text()
    import json

    policy = json.loads((tmp_path / "o" / "summary.json").read_text())["policy"]
    assert policy["action_space"] == "joint_position" and policy["said_done"]
    assert policy["steps"] > 100 and policy["clipped"] == 0


# --- bad input and bad policies ------------------------------------------------------------

BAD = """
import numpy as np


class Bad:
    def __init__(self, answer):
        self.answer = answer

    def reset(self, task, seed):
        pass

    def act(self, observation):
        return self.answer(observation)


def wrong_shape():
    return Bad(lambda o: np.zeros(3))


def nan():
    return Bad(lambda o: np.full(7, np.nan))


def raises():
    def boom(o):
        raise RuntimeError("the network is not loaded")
    return Bad(boom)


def strings():
    return Bad(lambda o: "move left")


def one_tuple():
    return Bad(lambda o: (np.zeros(7),))


def three_tuple():
    return Bad(lambda o: (np.zeros(7), False, 1))


def maybe_done():
    return Bad(lambda o: (np.zeros(7), "maybe"))


def a_dict():
    return Bad(lambda o: {"dx": 0.0})


def slow():
    import time

    def think(o):
        time.sleep(2.0)
        return np.zeros(7)
    return Bad(think)
"""


@pytest.mark.parametrize(
    "factory, words",
    [
        ("bad:wrong_shape", "returned an action of shape (3,); a ee_delta action has shape (7,)"),
        ("bad:nan", "returned a non-finite ee_delta action"),
        ("bad:raises", "raised RuntimeError: the network is not loaded"),
        ("bad:strings", "returned str 'move left'"),
        ("bad:one_tuple", "returned a tuple of 1; act() returns an action, or (action, done)"),
        ("bad:three_tuple", "returned a tuple of 3"),
        ("bad:maybe_done", "returned done = 'maybe' (str); done is a bool"),
        ("bad:a_dict", "returned dict {'dx': 0.0}"),
    ],
)
def test_a_bad_policy_is_one_line_and_exit_3(tmp_path, factory, words):
    (tmp_path / "bad.py").write_text(BAD)
    (tmp_path / "s.yaml").write_text(
        f"reference: !Policy {{factory: {factory}, action_space: ee_delta}}\n"
    )
    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.run", "--scenario", "s.yaml", "--out", "o", "--quiet"],
        capture_output=True, text=True, timeout=300, cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": f"{tmp_path}{os.pathsep}{ROOT}"},
    )  # fmt: skip
    assert r.returncode == 3, r.stderr
    assert "Traceback" not in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert f"policy '{factory}'" in r.stderr and words in r.stderr, r.stderr
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "text, words",
    [
        ("reference: !Policy {action_space: ee_delta}", "needs a factory"),
        ("reference: !Policy {factory: expert, action_space: ee_delta}", "is module:attribute"),
        ("reference: !Policy {factory: examples.expert_policy:make, action_space: fly}",
         "action_space 'fly'; choose one of: joint_position, ee_delta, joint_chunk"),
        ("reference: !Policy {factory: examples.expert_policy:make, rate_hz: 0}",
         "reference.rate_hz = 0.0 is outside"),
        ("reference: !Policy {factory: examples.expert_policy:make, act_budget_s: 0}",
         "reference.act_budget_s = 0.0 is outside"),
        ("reference: !Policy {factory: examples.expert_policy:make, action_space: joint_chunk,"
         " options: {horizon: 4, execute: 9}}", "1 <= execute <= horizon"),
        ("reference: !Policy {factory: examples.expert_policy:make, action_space: joint_chunk,"
         " options: {horizon: 2.5}}", "horizon = 2.5: a whole number"),
        ("reference: !Policy {factory: examples.expert_policy:make, action_space: joint_chunk,"
         " options: {horizon: 1000000000}}", "from 1 to 100"),
    ],
)  # fmt: skip
def test_a_policy_that_cannot_run_is_refused_before_anything_is_built(text, words):
    s = parse_scenario(text + "\n", "s.yaml")
    with pytest.raises(InputError, match=words.replace("(", r"\(")):
        check(s, write=False)


@pytest.mark.parametrize(
    "command",
    ["record", "evaluate"],
)
@pytest.mark.parametrize(
    "factory, words",
    [
        ("bad:one_tuple", "returned a tuple of 1"),
        ("bad:maybe_done", "returned done = 'maybe' (str)"),
        ("bad:a_dict", "returned dict {'dx': 0.0}"),
        ("bad:wrong_shape", "returned an action of shape (3,)"),
    ],
)
def test_a_bad_answer_names_the_users_policy_in_record_and_evaluate(
    tmp_path, command, factory, words
):
    (tmp_path / "bad.py").write_text(BAD)
    (tmp_path / "s.yaml").write_text(
        "task: {generate: {blocks: 2}}\n"
        "reference: !Policy {factory: bad:wrong_shape, action_space: ee_delta, max_steps: 5}\n"
    )
    args = ["--out", "o", "--episodes", "1", "--workers", "1"]
    args = ["s.yaml", "--policy", factory, *args] if command == "record" else [factory,
            "--suite", "s.yaml", *args]  # fmt: skip
    r = failed_in(tmp_path, command, *args)
    assert f"policy '{factory}'" in r.stderr and words in r.stderr, r.stderr
    assert "HeldAction" not in r.stderr


def failed_in(folder: Path, command: str, *args: str) -> subprocess.CompletedProcess:
    """``python -m cake_drake.COMMAND ARGS`` run in ``folder`` (its modules importable),
    checked to have ended in one line with exit 3."""
    r = subprocess.run(
        [sys.executable, "-m", f"cake_drake.{command}", *args],
        capture_output=True, text=True, timeout=300, cwd=folder,
        env={**os.environ, "PYTHONPATH": f"{folder}{os.pathsep}{ROOT}"},
    )  # fmt: skip
    assert r.returncode == 3, r.stderr
    assert "Traceback" not in r.stderr and r.stderr.count("\n") == 1, r.stderr
    return r


@pytest.mark.parametrize("command", ["run", "record", "evaluate"])
def test_a_policy_past_the_scenarios_budget_for_one_answer_is_one_line_and_exit_3(
    tmp_path, command
):
    """``reference.act_budget_s`` is the budget of one ``act`` wherever the policy runs:
    the Diagram (run), and the Gym episodes of record and evaluate."""
    (tmp_path / "bad.py").write_text(BAD)
    (tmp_path / "s.yaml").write_text(
        "task: {generate: {blocks: 2}}\n"
        "reference: !Policy {factory: bad:slow, action_space: ee_delta, max_steps: 5,"
        " act_budget_s: 0.5}\n"
    )
    args = ["--out", "o", "--episodes", "1", "--workers", "1"]
    args = {
        "run": ["--scenario", "s.yaml", "--out", "o", "--quiet"],
        "record": ["s.yaml", *args],
        "evaluate": ["bad:slow", "--suite", "s.yaml", *args],
    }[command]
    r = failed_in(tmp_path, command, *args)
    assert "policy 'bad:slow' overran its budget of 0.5 s" in r.stderr, r.stderr
    if command != "record":  # a recording keeps the episodes that finished: none here
        assert not (tmp_path / "o").exists()


# --- Gymnasium -------------------------------------------------------------------------------


def test_the_environment_passes_gymnasiums_checker():
    from gymnasium.utils.env_checker import check_env

    env = gymnasium.make(ENV_ID, blocks=3, obs_mode="state+rgb")
    check_env(env.unwrapped, skip_render_check=True)


def _bytes(x) -> list[bytes]:
    """Every array in ``x`` (nested dicts, lists, tuples) as bytes, in order."""
    if isinstance(x, dict):
        return [b for k in sorted(x) for b in _bytes(x[k])]
    if isinstance(x, list | tuple) and not all(isinstance(v, str) for v in x):
        return [b for v in x for b in _bytes(v)]
    return [np.asarray(x).tobytes()]


@pytest.mark.parametrize("mode", ["state", "state+rgb"])
def test_a_seeded_reset_and_the_same_actions_give_the_same_episode_bit_for_bit(mode):
    runs = []
    for _ in range(2):
        env = gymnasium.make(ENV_ID, blocks=(3, 6), obs_mode=mode)
        obs, info = env.reset(seed=7)
        env.action_space.seed(3)
        trace = [obs, info["goal"]]
        for _ in range(5):
            obs, reward, *_ = env.step(env.action_space.sample())
            trace += [obs, reward]
        runs.append(trace)
    assert _bytes(runs[0]) == _bytes(runs[1])


def test_another_seed_gives_another_problem():
    env = gymnasium.make(ENV_ID, blocks=(3, 8))
    goals = {env.reset(seed=s)[1]["goal"] for s in range(4)}
    assert len(goals) > 1


def test_two_environments_run_on_two_processes():
    envs = gymnasium.vector.AsyncVectorEnv(
        [lambda: gymnasium.make(ENV_ID, blocks=3, obs_mode="state") for _ in range(2)]
    )
    try:
        obs, info = envs.reset(seed=[1, 2])
        assert obs["state"].shape == (2, 22)
        for _ in range(3):
            obs, reward, terminated, truncated, info = envs.step(envs.action_space.sample())
        assert reward.shape == (2,) and np.all((reward >= 0) & (reward <= 1))
    finally:
        envs.close()


@pytest.mark.slow
@pytest.mark.parametrize(
    "mode, options", [("ee_delta", {}), ("joint_chunk", {"horizon": 10, "execute": 5})]
)
def test_the_expert_builds_problem_5_through_the_environment(mode, options):
    from examples.expert_policy import make

    obs_mode = "state+rgb" if mode == "ee_delta" else "state"
    env = gymnasium.make(
        ENV_ID, problem=str(PROBLEM_5), control_mode=mode, obs_mode=obs_mode, options=options
    )
    obs, info = env.reset(seed=0)
    assert info["task"] == "stack a on b, b on c, c on d, d on e, with e on the table"
    expert = make()
    expert.reset(env.unwrapped.policy_task, 0)
    terminated = truncated = False
    while not (terminated or truncated):
        action = expert.act(obs)
        assert not isinstance(action, tuple), "the expert ended before the goal held"
        obs, reward, terminated, truncated, info = env.step(action)
    assert info["is_success"] and reward == 1.0


def test_bad_environment_options_are_one_line():
    with pytest.raises(InputError, match="obs_mode 'depth'; choose one of"):
        gymnasium.make(ENV_ID, obs_mode="depth")
    with pytest.raises(InputError, match="action_space 'velocity'"):
        gymnasium.make(ENV_ID, control_mode="velocity")


def test_no_generated_episode_starts_with_its_goal_already_holding():
    env = gymnasium.make(ENV_ID, blocks=(3, 8))
    starts = [env.reset(seed=s)[1] for s in range(30)]
    assert not any(info["is_success"] for info in starts)  # seed 25 drew one, now drawn again


def test_a_hand_frame_move_keeps_the_hand_pointing_down_whatever_it_asks():
    """ee_target with ``down``: from a tilted hand, asked to roll, pitch and turn, the hand
    ends pointing straight down, turned by the measured yaw plus dyaw only."""
    from pydrake.math import RigidTransform, RollPitchYaw

    from cake_drake.geometric.ik import DlsIk, Kinematics
    from cake_drake.policy.spaces import Counts, ee_target
    from cake_drake.world.scene import Q_HOME

    kin = Kinematics()
    ik = DlsIk(kin)
    home = kin.pose(Q_HOME)
    tilt = RollPitchYaw(0.15, -0.1, 0.0).ToRotationMatrix()
    X_WG = RigidTransform(tilt.multiply(home.rotation()), home.translation())
    R0 = X_WG.rotation().matrix()
    yaw0 = np.arctan2(R0[1, 0], R0[0, 0])
    counts = Counts()
    for droll, dpitch, dyaw in ((0.3, 0.0, 0.0), (0.0, -0.3, 0.2), (0.2, 0.2, -0.3)):
        delta = np.array([0.01, -0.01, 0.02, droll, dpitch, dyaw])
        q = ee_target(delta, X_WG, ik, Q_HOME, counts, down=True)
        assert q is not None and counts.unreachable == 0
        R = kin.pose(q).rotation().matrix()
        assert np.allclose(R[:, 2], [0.0, 0.0, -1.0], atol=1e-3), R  # the hand's z: down
        yaw = np.arctan2(R[1, 0], R[0, 0])
        assert abs(np.angle(np.exp(1j * (yaw - yaw0 - dyaw)))) < 1e-3
        assert np.allclose(kin.pose(q).translation(), X_WG.translation() + delta[:3], atol=1e-3)
    # Without ``down`` the same asks tilt the hand: the test above can tell the two apart.
    q = ee_target(np.array([0, 0, 0, 0.3, 0, 0]), X_WG, ik, Q_HOME, counts)
    assert not np.allclose(kin.pose(q).rotation().matrix()[:, 2], [0, 0, -1], atol=1e-2)
