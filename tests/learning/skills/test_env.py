"""``CakeDrake/Skill-v0``: one ground action of the shipped relative skill an episode, in
the Diagram a run with learned skills builds (Drake, the planner and the skill all real)."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from cake_drake.errors import InputError
from cake_drake.learning.envs import rewards
from cake_drake.policy.observations import RELATIVE_SIZE
from cake_drake.scenario import Reward

ENV_ID = "cake_drake.gym:CakeDrake/Skill-v0"


def test_it_passes_gymnasium_s_checker():
    env = gymnasium.make(ENV_ID, blocks=(3, 4))
    check_env(env.unwrapped, skip_render_check=True)
    assert env.observation_space.shape == (RELATIVE_SIZE,) and env.action_space.shape == (7,)


def _lead_episode(env, seed: int):
    obs, info = env.reset(seed=seed)
    first, rows = info, []
    lead = env.unwrapped._lead
    while True:
        obs, reward, terminated, truncated, info = env.step(lead.act({"observation.relative": obs}))
        rows.append((reward, info))
        if terminated or truncated:
            return first, rows, terminated


def test_an_episode_is_one_place_and_its_reward_is_the_weighted_terms():
    weights = {"goal": 1.0, "success": 8.0, "place": 2.0, "step": -0.25, "reach": 0.5}
    env = gymnasium.make(ENV_ID, blocks=(3, 5), reward=weights)
    reward = rewards.check_reward(weights)
    outcomes = []
    for seed in range(2):
        first, rows, terminated = _lead_episode(env, seed)
        assert first["action"] in ("stack", "put-down") and first["steps"] == 0
        for r, info in rows:  # every step's reward is its terms, weighed
            assert r == pytest.approx(rewards.weighted(reward, info["reward_terms"]))
            assert info["action"] == first["action"]
        last = rows[-1][1]
        # a place's offset at its end pays the place term: 1 centred, 0 from 10 mm
        place = last["reward_terms"]["place"]
        assert place == pytest.approx(max(0.0, 1.0 - last["offset_mm"] / 10.0))
        assert last["is_success"] == (last["reward_terms"]["goal"] == 1.0
                                      and last["offset_mm"] <= 5.0)  # fmt: skip
        assert all(info["reward_terms"]["goal"] == 0.0 for _, info in rows[:-1])
        outcomes.append((terminated, last["is_success"], len(rows)))
    # the shipped skill's own answers end most of its places with their effects
    assert sum(s for _, s, _ in outcomes) >= 1, outcomes
    assert all(t or n >= 140 for t, _, n in outcomes), outcomes


def test_the_same_seed_gives_the_same_start():
    env = gymnasium.make(ENV_ID, blocks=(3, 6))
    a, _ = env.reset(seed=11)
    b, _ = env.reset(seed=11)
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"actions": ["place"]}, "actions = ['place']: the kinds of action an episode may be"),
        ({"blocks": 1, "actions": "stack"}, "every problem of one cube holds its goal"),
        ({"blocks": 1, "actions": "places"}, "every problem of one cube holds its goal"),
        ({"blocks": (1, 1), "actions": "picks"}, "give 2 blocks or more"),
        ({"budget": 0}, "budget = 0: control periods an action may take"),
        ({"skill": "package://cake_drake/policies/stack2"}, "not a learned skill"),
        ({"reward": {"plce": 1.0}}, "reward.plce: no such reward term"),
    ],
)
def test_an_environment_that_cannot_start_is_refused_when_made(kwargs, words):
    with pytest.raises(InputError, match=words.replace("[", r"\[").replace("]", r"\]")):
        gymnasium.make(ENV_ID, **kwargs)


@pytest.mark.parametrize(
    "action", [np.full(7, np.nan), np.zeros(3)], ids=["not-finite", "too-short"]
)
def test_an_action_outside_the_space_is_the_caller_s_not_the_skill_s(action):
    env = gymnasium.make(ENV_ID, blocks=(3, 3))
    env.reset(seed=3)
    with pytest.raises(InputError, match=r"^CakeDrake/Skill-v0 step\(\): action \[.*; the "
                       "action space is 7 finite numbers$"):  # fmt: skip
        env.step(action)


def test_its_reward_terms_are_the_stack_env_s_names():
    env = gymnasium.make(ENV_ID, blocks=(2, 3))
    _, info = env.reset(seed=0)
    assert set(info["reward_terms"]) == {f for f in Reward.__dataclass_fields__}


def test_the_fingers_move_at_their_speed_whatever_the_skill_decides():
    """A gripper decision comes as a step (open, then closed at once); the fingers'
    command moves at their speed (``FINGER_SPEED``, as the classical layer's close and
    every demonstrator's): closed round a pick's cube, the first control period ends
    with the fingers a cube's width apart, on it. A step command slammed them shut in one
    period, and the cube they closed on was kicked round in the grasp."""
    from cake_drake.policy.shield import FINGER_SPEED

    env = gymnasium.make(ENV_ID, blocks=(3, 4), actions="picks", rate_hz=10.0)
    obs, info = env.reset(seed=0)
    assert info["action"] in ("pick-up", "unstack") and obs[-1] > 0.079  # open, high up
    lead = env.unwrapped._lead
    for _ in range(100):  # the demonstrator's moves down to the cube, the fingers open
        if np.abs(obs[4:7]).max() < 0.006 and obs[-1] > 0.079:
            break
        obs, *_ = env.step(np.r_[lead.act({"observation.relative": obs})[:6], 1.0])
    else:
        pytest.fail(f"the hand never came round the cube: {obs[4:7]}")
    stay_and_close = np.zeros(7)
    widths = []
    for _ in range(3):
        obs, *_ = env.step(stay_and_close)
        widths.append(float(obs[-1]))
    a_period = 2 * FINGER_SPEED * 0.1  # m of width
    assert widths[0] == pytest.approx(0.08 - a_period, abs=0.003), widths
    assert all(0.03 < w < 0.042 for w in widths[1:]), widths  # on the cube, not shut
