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
    from cake_drake.systems.skills import FINGER_SPEED

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


def test_a_skill_blind_to_quarter_turns_keeps_the_wrist_mid_range():
    """A skill that reads yaws modulo a quarter turn answers a turn nearest the hand's
    yaw; action after action, the wrist wound up to its joint limit. The hand instead
    turns towards the quarter turn of the answer nearest the comfortable yaw over the
    action's target (the classical layer's), chosen at the action's first period and
    kept, at most the step's limit a period."""
    from types import SimpleNamespace

    from pydrake.math import RigidTransform, RotationMatrix

    from cake_drake.geometric.waypoints import WaypointParams
    from cake_drake.learning.policies.relative_skill import RelativeSkill
    from cake_drake.systems.skills import LearnedSkills, SkillProgress

    assert RelativeSkill.free_quarter_turns
    system = SimpleNamespace(_params=WaypointParams())
    turn = lambda prog, hand, dyaw: LearnedSkills._wrist_turn(system, prog, cubes, hand, dyaw, 0.25)  # noqa: E731
    hand_at = lambda yaw, p: RigidTransform(RotationMatrix.MakeZRotation(yaw), p)  # noqa: E731
    pick = SkillProgress(context=SimpleNamespace(target=None, cube="a"))
    cubes = {"a": RigidTransform([0.5, 0.0, 0.02])}  # straight ahead: comfortable yaw 0
    # Its answer turns the hand 0.05 rad on, to 2.05; the same grasp is 2.05 - 90 deg.
    step, wrist = turn(pick, hand_at(2.0, [0.45, 0.0, 0.2]), 0.05)
    assert step == pytest.approx(-0.25) and wrist == pytest.approx(2.05 - np.pi / 2)
    # Kept through the action: from the half-way yaw, still towards the chosen one.
    kept = SkillProgress(context=pick.context, wrist=wrist)
    half_way = wrist + np.pi / 4 + 0.05
    step, again = turn(kept, hand_at(half_way, [0.45, 0.0, 0.2]), 0.0)
    assert step == pytest.approx(-0.25) and again == wrist
    step, _ = turn(kept, hand_at(wrist + 0.1, [0.45, 0.0, 0.2]), -0.1)
    assert step == pytest.approx(-0.1)  # there: its own answer
    # A place: the comfortable yaw over where the cube goes (to the left: 90 deg).
    place = SkillProgress(context=SimpleNamespace(target=np.array([0.0, 0.5, 0.02]), cube="a"))
    step, wrist = turn(place, hand_at(np.pi / 2 + 0.1, [0.0, 0.45, 0.2]), 0.0)
    assert step == pytest.approx(0.0) and wrist == pytest.approx(np.pi / 2 + 0.1)
    step, _ = turn(place, hand_at(0.1, [0.0, 0.45, 0.2]), 0.0)
    assert step == pytest.approx(0.25)  # the same grasp turned a quarter, a step at a time


def test_a_far_destination_is_read_on_the_way_around_the_arms_base():
    """Towers on opposite sides of the table: the straight line between them passes 7 cm
    from the arm's base, where no top-down hand reaches (the elbow folded to its limit
    on a generated ten-cube problem). A skill that never sees the arm reads a destination
    further across than ``AROUND`` as the point that far on the way around the base;
    walked step by step, the hand keeps to the towers' arc and arrives."""
    from types import SimpleNamespace

    from pydrake.math import RigidTransform

    from cake_drake.geometric.waypoints import around_base
    from cake_drake.policy.observations import SKILL_SIZE
    from cake_drake.systems.skills import AROUND, LearnedSkills
    from cake_drake.world.scene import SLOTS

    right, left = SLOTS[-2], SLOTS[-1]  # the outermost slots, either side
    assert np.hypot(*right) == pytest.approx(0.55) and right[1] * left[1] < 0
    (x0, y0), (x1, y1) = right, left
    chord = abs(x0 * y1 - x1 * y0) / np.hypot(x1 - x0, y1 - y0)
    assert chord < 0.1  # the straight line's nearest point to the base
    hand, steps = np.array(right), 0
    while not np.allclose(hand, left):
        ahead = around_base(hand, left, AROUND)
        assert np.hypot(*(ahead - hand)) == pytest.approx(AROUND, abs=0.01) or (ahead == left).all()
        assert np.hypot(*ahead) > 0.54  # on the arc, never across the base
        hand, steps = ahead, steps + 1
        assert steps < 20
    assert steps == int(np.ceil(0.55 * 2 * np.arctan2(abs(left[1]), left[0]) / AROUND))  # 11
    np.testing.assert_array_equal(around_base([0.5, 0.0], [0.5, 0.1], AROUND), [0.5, 0.1])

    # What the skill reads: a pick's cube and target move by the same step; a place's
    # held cube stays in the hand; a near destination reads as it is, the same array.
    X_WG = RigidTransform([right[0], right[1], 0.3])
    far = np.zeros(SKILL_SIZE, np.float32)
    far[4:6] = far[8:10] = np.subtract(left, right)
    far[6], far[10] = -0.28, 0.0
    pick = SimpleNamespace(target=None)
    read = LearnedSkills._around(None, pick, far, X_WG)
    ahead = around_base(right, left, AROUND)
    np.testing.assert_allclose(read[4:6], ahead - right, atol=1e-6)
    np.testing.assert_allclose(read[8:10], ahead - right, atol=1e-6)
    np.testing.assert_array_equal(read[[6, 10]], far[[6, 10]])
    place = far.copy()
    place[4:7] = [0.0, 0.0, -0.012]
    read = LearnedSkills._around(None, SimpleNamespace(target=np.zeros(3)), place, X_WG)
    np.testing.assert_array_equal(read[4:7], place[4:7])
    np.testing.assert_allclose(read[8:10], ahead - right, atol=1e-6)
    near = far.copy()
    near[4:6] = near[8:10] = [0.05, 0.05]
    assert LearnedSkills._around(None, pick, near, X_WG) is near


def test_a_hand_stopped_short_of_where_it_was_sent_takes_its_next_move_from_there():
    """Under a 0.5 kg cube the hand held a stack 9 mm across from its place and the
    skill, answering the 9 mm from the measured hand period after period, sent it to the
    same place: the shortfall never added up. A hand that has stopped (moved less than
    ``STILL`` in a period) takes its next move from where it was last sent, at most
    ``LEAD`` on; a moving hand, or the first period of an action, from where it is."""
    from pydrake.math import RigidTransform

    from cake_drake.geometric.ik import Kinematics
    from cake_drake.systems.skills import LEAD, STILL, LearnedSkills, SkillProgress

    last = np.array([0.0, 0.1, 0.0, -2.2, 0.0, 2.3, 0.8])  # the joints it was sent to
    sent = Kinematics().pose(last)
    to = sent.translation()
    hand = RigidTransform(sent.rotation(), sent.translation() - [0.004, 0.009, 0.0])
    p = hand.translation()

    def base(was):
        prog = SkillProgress(hand=None if was is None else tuple(was))
        return LearnedSkills._short(prog, hand, to).translation()

    np.testing.assert_allclose(base(p + [0.0, 0.0, STILL / 2]), sent.translation())
    np.testing.assert_array_equal(base(p + [0.0, 2 * STILL, 0.0]), p)  # still moving
    np.testing.assert_array_equal(base(None), p)  # the action's first period
    far = RigidTransform(sent.rotation(), sent.translation() - [0.0, 0.05, 0.0])
    prog = SkillProgress(hand=tuple(far.translation()))
    np.testing.assert_allclose(
        LearnedSkills._short(prog, far, to).translation(),
        far.translation() + [0.0, LEAD, 0.0],
    )


def test_a_hand_goes_down_only_once_over_where_it_goes_down_to():
    """An unstack's hand came down while still 4 cm across from its cube; the leading
    finger landed on the cube's top and knocked it off its tower (problem_5). While more
    than ``ALIGNED`` across from where it goes down to, a hand goes no lower than the
    classical pre-grasp height above it (``approach``), and a hand already lower goes no
    lower; over it, or going up, the skill's move is taken as it is."""
    from types import SimpleNamespace

    from pydrake.math import RigidTransform

    from cake_drake.geometric.waypoints import WaypointParams
    from cake_drake.systems.skills import ALIGNED, LearnedSkills

    system = SimpleNamespace(_params=WaypointParams())
    approach = WaypointParams().approach
    cube = np.array([0.565, -0.097, 0.06])  # the top of a two-cube tower
    cubes = {"b": RigidTransform(cube), "a": RigidTransform([0.47, -0.29, 0.02])}
    unstack = SimpleNamespace(cube="b", target=None, other="a")

    def down(action, hand, dz, base=None):
        X_WG = RigidTransform(hand)
        return LearnedSkills._over(system, action, cubes, X_WG, base or X_WG, [0.0, 0.0, dz])

    high = cube + [0.0, -0.042, 0.08]  # 4.2 cm across, 8 cm above
    assert down(unstack, high, -0.05) == pytest.approx(approach - 0.08)  # to 6 cm above
    assert down(unstack, cube + [0.0, -0.042, 0.041], -0.033) == 0.0  # lower already
    assert down(unstack, high, 0.02) == 0.02  # going up
    over = cube + [ALIGNED * 0.7, -ALIGNED * 0.7, 0.041]
    assert down(unstack, over, -0.033) == -0.033
    # From where it was last sent (a stopped hand's base), 2 cm above where it is.
    sent = RigidTransform(high + [0.0, 0.0, 0.02])
    assert down(unstack, high, -0.05, sent) == pytest.approx(approach - 0.1)

    # A place: where the hand goes down to is the target, less the cube in the hand.
    target = np.array([0.47, -0.29, 0.06])  # onto "a"
    stack = SimpleNamespace(cube="b", target=target, other="a")
    off = np.array([0.003, -0.002, 0.001])  # the hand, from the cube in its fingers

    def holding(cube_at):
        cubes["b"] = RigidTransform(cube_at)
        return cube_at + off

    assert down(stack, holding(target + [0.2, 0.1, 0.2]), -0.05) == -0.05  # 20 cm above
    assert down(stack, holding(target + [0.03, 0.0, 0.07]), -0.03) == pytest.approx(approach - 0.07)
    assert down(stack, holding(target + [0.005, 0.0, 0.07]), -0.03) == -0.03  # over it


def test_a_crossing_hand_keeps_above_the_towers_beside_its_way():
    """Set off from the top of a five-cube tower it had just stacked on, a hand went down
    at once toward a cube on the table and its fingers swept the tower's top cube off; a
    cube carried down toward the table met a two-cube tower on its way (eight cubes in
    tall towers). While crossing, a hand keeps ``approach`` above every cube within
    ``REACH`` of its way this period, as well as above where it goes down to."""
    from types import SimpleNamespace

    from pydrake.math import RigidTransform

    from cake_drake.geometric.waypoints import WaypointParams
    from cake_drake.systems.skills import AROUND, REACH, LearnedSkills

    system = SimpleNamespace(_params=WaypointParams())
    approach = WaypointParams().approach
    top = np.array([0.541, -0.1, 0.18])  # a five-cube tower's top cube
    cubes = {
        "d": RigidTransform(top),
        "e": RigidTransform(top + [0.0, 0.12, -0.16]),  # on the table, 12 cm across
        "f": RigidTransform(top + [0.0, -0.21, -0.16]),  # on the table, the other side
    }
    hand = RigidTransform(top + [0.0, 0.0, 0.069])

    def down(move, at=hand, cube="e"):
        pick = SimpleNamespace(cube=cube, target=None, other=None)
        assert np.hypot(*(cubes[cube].translation() - at.translation())[:2]) < AROUND
        return LearnedSkills._over(system, pick, cubes, at, at, move)

    # Off toward the table cube: held at the tower's top cube + approach, not the table's.
    assert down([0.007, 0.02, -0.033]) == pytest.approx(approach - 0.069)
    # The same move from a hand further than REACH from the tower: down as answered.
    away = RigidTransform(top + [0.0, REACH + 0.01, 0.069])
    assert down([0.0, 0.02, -0.033], away) == -0.033
    # A tower behind the hand (on the line of its way, not within REACH of it): no bar.
    beyond = RigidTransform(top + [0.0, -(REACH + 0.03), 0.069])
    assert down([0.0, -0.01, -0.033], beyond, "f") == -0.033
    # A hand already lower than the bar goes no lower, and goes up when it answers up.
    low = RigidTransform(top + [0.0, 0.03, 0.03])
    assert down([0.0, 0.02, -0.02], low) == 0.0
    assert down([0.0, 0.02, 0.01], low) == 0.01


def test_a_hand_far_from_where_it_goes_down_to_keeps_to_the_transit_height():
    """A put-down that left the home height for a spot beyond an eight-cube tower went down
    5 cm a period while the tower was still further than ``REACH`` from its way; once
    within it, held no lower, its cube pushed the tower's second cube 16 mm (ten cubes in
    tall towers). Further than ``AROUND`` across from where it goes down to, the hand keeps
    to the classical transit height of every cube but the one it holds, rising to it at
    most a step (5 cm) a period; going up, or above it, the skill's move is taken."""
    from types import SimpleNamespace

    from pydrake.math import RigidTransform

    from cake_drake.geometric.waypoints import WaypointParams, transit_height
    from cake_drake.systems.skills import AROUND, LearnedSkills

    params = WaypointParams()
    system = SimpleNamespace(_params=params)
    tower = np.array([0.5, 0.0, 0.02 + 7 * 0.04])  # an eight-cube tower's top cube
    held = np.array([0.5, 0.25, 0.30])  # a cube in the hand, 25 cm across from the tower
    cubes = {"h": RigidTransform(tower), "c": RigidTransform(held)}
    spot = np.array([0.5, -0.2, 0.02])  # a put-down's spot beyond the tower
    put = SimpleNamespace(cube="c", target=spot, other=None)
    transit = transit_height({"h": cubes["h"]}, None, params)
    assert transit == pytest.approx(tower[2] + 0.04 + params.transit_clearance)

    def down(hand_z, dz, action=put):
        X_WG = RigidTransform([0.5, 0.25, hand_z])
        assert np.hypot(*(action.target - held)[:2]) > AROUND
        return LearnedSkills._over(system, action, cubes, X_WG, X_WG, [0.0, -0.03, dz])

    assert down(transit + 0.02, -0.05) == pytest.approx(-0.02)  # down to it, no lower
    assert down(transit - 0.08, -0.05) == pytest.approx(0.05)  # below: up a step a period
    assert down(transit - 0.01, -0.05) == pytest.approx(0.01)  # the last centimetre
    assert down(transit - 0.08, 0.05) == 0.05  # going up: as answered
    assert down(transit + 0.2, -0.05) == -0.05  # well above: as answered
    # A pick far off: the cube it goes for (the top of a nine-cube tower) is not held.
    cubes["c"] = RigidTransform(tower + [0.0, -0.2, 0.04])
    pick = SimpleNamespace(cube="c", target=None, other=None)
    far = transit_height(cubes, None, params)
    X_WG = RigidTransform([0.5, 0.25, far])
    assert LearnedSkills._over(system, pick, cubes, X_WG, X_WG, [0.0, -0.03, -0.05]) == 0.0


def test_the_fingers_close_only_around_the_cube_and_open_only_where_it_rests():
    """From a home pose 2 cm over a ten-cube tower's top, a skill closed its fingers on air
    and sat over the cube as if it held it; carrying a cube across the table, a skill
    opened 15 cm short of its target and dropped it beside another tower; under 0.5 kg
    cubes a skill opened over its support still 5 to 15 mm across. A decision to close
    while the pick's cube is not between the fingers, or to open while the place's cube is
    in them and not resting on its target (a stack's within ``CENTRED`` across), is
    held."""
    from types import SimpleNamespace

    from pydrake.math import RigidTransform

    from cake_drake.systems.skills import CENTRED, SEATED, LearnedSkills

    fingers = SimpleNamespace(value=np.array([0.02, 0.02, 0.0, 0.0]))
    fingers.get_value = lambda: fingers.value
    context = SimpleNamespace(get_discrete_state=lambda group: fingers)
    system = SimpleNamespace(_groups={"finger_state": 0})

    def width(action, cube_at, hand_at, asked):
        cubes = {"e": RigidTransform(cube_at)}
        X_WG = RigidTransform(hand_at)
        return LearnedSkills._gripper(system, action, cubes, X_WG, asked, context)

    target = np.array([0.16, -0.52, 0.10])
    stack = SimpleNamespace(cube="e", target=target, other="d")
    far = target + [0.15, 0.05, 0.05]
    assert width(stack, far, far + [0.002, 0.0, 0.001], 0.08) == 0.04  # held: 15 cm short
    assert width(stack, far, far, 0.02) == 0.02  # closing further is the skill's to say
    above = target + [0.0, 0.0, SEATED + 0.005]
    assert width(stack, above, above, 0.08) == 0.04  # over it, still 1.5 cm up
    seated = target + [0.003, 0.0, 0.002]
    assert width(stack, seated, seated, 0.08) == 0.08  # resting on it, 3 mm across: let go
    off = target + [CENTRED + 0.001, 0.0, 0.002]
    assert width(stack, off, off, 0.08) == 0.04  # off centre by more than CENTRED: held
    put = SimpleNamespace(cube="e", target=target, other=None)  # a put-down's free spot
    seated = target + [0.015, 0.0, 0.002]
    assert width(put, seated, seated, 0.08) == 0.08  # 1.5 cm across: as good
    off = target + [0.025, 0.0, 0.002]
    assert width(put, off, off, 0.08) == 0.04  # more than half a cube across
    # Not in the fingers (dropped, or let go already): the skill's decision stands.
    assert width(stack, far, far + [0.0, 0.0, 0.06], 0.08) == 0.08

    fingers.value = np.array([0.04, 0.04, 0.0, 0.0])  # open
    unstack = SimpleNamespace(cube="e", target=None)
    top = np.array([0.541, -0.1, 0.38])  # a ten-cube tower's top cube
    home = top + [-0.078, 0.1, 0.023]
    assert width(unstack, top, home, 0.0) == 0.08  # 12 cm across: stays open
    assert width(unstack, top, top + [0.0, 0.0, 0.03], 0.0) == 0.08  # 3 cm over it
    assert width(unstack, top, top + [0.004, -0.003, 0.005], 0.0) == 0.0  # around it: closes
    assert width(unstack, top, home, 0.08) == 0.08  # opening is the skill's to say


def test_the_fingers_are_open_away_from_a_pick_s_cube_and_let_go_of_a_place_s():
    """Under 0.5 kg cubes a skill that had let go of its cube closed its fingers on air
    going back up, and the next pick began closed, a start no demonstration had: it
    hovered 9 cm over its cube, never opening; with a cube resting 6 mm from its spot on
    the table it answered a millimetre's move the pressed cube did not take, and no
    release, for three tries (``learned_cake``). Out of the fingers, a pick's cube is
    approached open and a place's, let go, is not closed on again; a place's hand stopped
    where its cube may be let go lets go."""
    from types import SimpleNamespace

    from pydrake.math import RigidTransform

    from cake_drake.systems.skills import GRIPPER_MAX, SEATED, LearnedSkills

    fingers = SimpleNamespace(value=np.zeros(4))
    fingers.get_value = lambda: fingers.value
    context = SimpleNamespace(get_discrete_state=lambda group: fingers)
    system = SimpleNamespace(_groups={"finger_state": 0})

    def width(action, cube_at, hand_at, asked, stopped=False):
        cubes = {"e": RigidTransform(cube_at)}
        X_WG = RigidTransform(hand_at)
        return LearnedSkills._gripper(system, action, cubes, X_WG, asked, context, stopped)

    cube = np.array([0.55, -0.08, 0.06])
    pick = SimpleNamespace(cube="e", target=None)
    assert width(pick, cube, cube + [0.0, 0.0, 0.086], 0.0) == GRIPPER_MAX  # 9 cm over it
    assert width(pick, cube, cube + [0.0, 0.0, 0.005], 0.0) == 0.0  # around it: closed

    fingers.value = np.array([0.04, 0.04, 0.0, 0.0])  # open
    spot = np.array([0.47, 0.28, 0.02])
    put = SimpleNamespace(cube="e", target=spot, other=None)
    assert width(put, spot, spot + [0.0, 0.0, 0.05], 0.0) == GRIPPER_MAX  # let go: stays open

    fingers.value = np.array([0.02, 0.02, 0.0, 0.0])  # holding the cube
    rests = spot + [0.001, -0.006, 0.002]  # on the table, 6 mm from its spot
    assert width(put, rests, rests, 0.0) == 0.0  # moving: the skill's to say
    assert width(put, rests, rests, 0.0, stopped=True) == GRIPPER_MAX  # stopped: let go
    above = spot + [0.0, 0.0, SEATED + 0.005]
    assert width(put, above, above, 0.0, stopped=True) == 0.0  # stopped in the air: held


def test_a_place_s_hand_goes_back_up_clear_of_the_cube_it_placed():
    """Stacked on the tallest tower, the cube rose above the transit height of the towers
    as they stood; the skill went back up to that height and sat 4 mm under where the
    action counts as done. Once the fingers have let go, the transit height it reads is
    the classical retract's, clear of the placed cube, where the action's own is lower."""
    from types import SimpleNamespace

    from pydrake.math import RigidTransform

    from cake_drake.geometric.waypoints import WaypointParams
    from cake_drake.systems.skills import LearnedSkills

    system = SimpleNamespace(_params=WaypointParams())
    clearance = WaypointParams().transit_clearance
    cube = np.array([0.164, -0.517, 0.26])
    cubes = {"g": RigidTransform(cube)}
    stack = SimpleNamespace(cube="g", target=cube)
    hand = RigidTransform(cube + [0.0, 0.0, 0.066])
    skill = np.zeros(13, np.float32)
    skill[12] = 0.31 - 0.326  # the action's transit height, 1.6 cm under the hand

    def read(width, action=stack):
        return LearnedSkills._clear(system, action, cubes, skill, hand, width)

    after = 0.26 + 0.04 + clearance - 0.326
    assert read(0.08)[12] == pytest.approx(after)  # let go: up clear of the cube
    assert read(0.04)[12] == skill[12]  # still holding it: the action's own
    assert read(0.08, SimpleNamespace(cube="g", target=None))[12] == skill[12]  # a pick
    skill[12] = 0.2
    assert read(0.08)[12] == pytest.approx(0.2)  # the action's own is higher already


def test_a_held_back_hand_is_held_where_it_was_sent_and_a_put_down_is_over_half_a_cube():
    """Under a 0.5 kg cube the hand sags below where it is sent: held where it was
    measured each period, it crept down a centimetre every few periods while still
    across from its place. A hand held back goes no lower than where it was last sent;
    and a put-down's place, a free spot of the table, counts as under the hand within
    half a cube (the hand stood 1.5 cm short of it, held, until its tries ran out)."""
    from types import SimpleNamespace

    from pydrake.math import RigidTransform

    from cake_drake.geometric.waypoints import WaypointParams
    from cake_drake.systems.skills import LearnedSkills

    system = SimpleNamespace(_params=WaypointParams())
    target = np.array([0.47, 0.27, 0.02])
    at = target + [0.015, -0.015, 0.045]  # 2.1 cm across, 4.5 cm up
    cubes = {"b": RigidTransform(at)}
    stack = SimpleNamespace(cube="b", target=target, other="a")
    put_down = SimpleNamespace(cube="b", target=target, other=None)
    hand = RigidTransform(at)

    def down(action, move, sent=None):
        return LearnedSkills._over(system, action, cubes, hand, hand, move, sent)

    assert down(stack, [0.0, 0.0, -0.01]) == 0.0  # no lower than it is
    assert down(stack, [0.0, 0.0, -0.01], sent=at[2] + 0.006) == pytest.approx(0.006)
    assert down(stack, [0.0, 0.0, -0.01], sent=at[2] - 0.004) == 0.0  # sent lower: as is
    assert down(put_down, [0.0, 0.0, -0.01]) == 0.0  # 2.1 cm: more than half a cube
    cubes["b"] = hand = RigidTransform(target + [0.012, -0.012, 0.045])  # 1.7 cm
    assert down(put_down, [0.0, 0.0, -0.01]) == -0.01
    assert down(stack, [0.0, 0.0, -0.01]) == 0.0
