"""The shield's steps (cake_drake.policy.shield), each on a hand-built case: what it
changes and what it leaves; and the list that names them, from a scenario to a run."""

from __future__ import annotations

import json
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest
from pydrake.math import RigidTransform, RotationMatrix

from cake_drake.geometric.waypoints import WaypointParams, around_base, transit_height
from cake_drake.policy import shield
from cake_drake.policy.observations import SKILL_SIZE
from cake_drake.policy.shield import (
    BESIDE_WAY_M,
    CATCH_UP_M,
    FAR_ACROSS,
    GRIPPER_MAX,
    OVER_M,
    RESTING_M,
    STILL_END_S,
    STILL_LET_GO_S,
    Answer,
    Period,
)
from cake_drake.world.facts import CENTRED
from cake_drake.world.scene import SLOTS
from tests.helpers import ROOT

PARAMS = WaypointParams()
GRIPPER = (
    "open_while_away",
    "close_only_around_cube",
    "stay_open_after_release",
    "open_only_where_resting",
    "let_go_when_resting_still",
)


def period(action, cubes, hand: RigidTransform, **kw) -> Period:
    return Period(action, cubes, hand, kw.pop("width", 0.08), PARAMS, 0.1, **kw)


def shaped(names, p: Period, move=(0.0,) * 6, width=0.08, base=None, wrist=None) -> Answer:
    """The answer after the steps ``names``, in their order."""
    a = Answer(np.asarray(move, float), width, base or p.X_WG, wrist)
    for name in names:
        a = shield.STEPS[name].run(p, a)
    return a


def test_the_steps_are_named_documented_and_checked():
    assert shield.DEFAULT == tuple(shield.STEPS)
    for step in shield.STEPS.values():
        assert step.phase in ("end", "observation", "action") and step.doc, step.name
        assert "\n" not in step.doc and step.doc.endswith((".", ")")), step.name
    assert shield.check_names([]) == ()
    with pytest.raises(ValueError, match="no step 'nope'; the steps are end_try_when_still, "):
        shield.check_names(["limit_finger_speed", "nope"])
    with pytest.raises(ValueError, match="named twice"):
        shield.check_names(["limit_finger_speed", "limit_finger_speed"])
    with pytest.raises(ValueError, match="a list of step names"):
        shield.check_names("limit_finger_speed")


def test_the_reference_lists_every_step_in_order_with_its_phase():
    lines = (ROOT / "docs" / "reference.md").read_text().split("\n")
    cells = [line.split(" | ") for line in lines if line.startswith("| `")]
    rows = [c for c in cells if len(c) == 3 and c[1] in ("end", "observation", "action")]
    assert [(c[0].strip("| `"), c[1]) for c in rows] == [
        (step.name, step.phase) for step in shield.STEPS.values()
    ]


def test_a_still_hand_ends_its_try():
    hand = RigidTransform([0.5, 0.0, 0.2])
    pick = SimpleNamespace(cube="a", target=None, other=None)
    ends = shield.STEPS["end_try_when_still"].run
    assert ends(period(pick, {}, hand, still_s=STILL_END_S))
    assert not ends(period(pick, {}, hand, still_s=STILL_END_S - 0.1))


def test_the_fingers_command_moves_at_their_speed():
    p = period(None, {}, RigidTransform(), fingers=0.08)
    most = 2 * shield.FINGER_SPEED * 0.1  # m of width a period
    assert shaped(["limit_finger_speed"], p, width=0.0).width == pytest.approx(0.08 - most)
    assert shaped(["limit_finger_speed"], p, width=0.075).width == pytest.approx(0.075)


def test_a_skill_blind_to_quarter_turns_keeps_the_wrist_mid_range():
    """The hand turns to the quarter turn of the answer nearest the comfortable yaw over
    the action's target, chosen at the action's first period and kept, at most the
    step's limit a period; a skill that reads yaws whole is left as it answered."""
    cubes = {"a": RigidTransform([0.5, 0.0, 0.02])}  # straight ahead: comfortable yaw 0
    pick = SimpleNamespace(target=None, cube="a")
    place = SimpleNamespace(target=np.array([0.0, 0.5, 0.02]), cube="a")  # 90 deg left

    def turn(action, yaw, at, dyaw, wrist=None):
        hand = RigidTransform(RotationMatrix.MakeZRotation(yaw), at)
        p = period(action, cubes, hand, max_turn=0.25, free_turns=True)
        a = shaped(["keep_wrist_mid_range"], p, move=[0, 0, 0, 0, 0, dyaw], wrist=wrist)
        return a.move[5], a.wrist

    # Its answer turns the hand 0.05 rad on, to 2.05; the same grasp is 2.05 - 90 deg.
    step, wrist = turn(pick, 2.0, [0.45, 0.0, 0.2], 0.05)
    assert step == pytest.approx(-0.25) and wrist == pytest.approx(2.05 - np.pi / 2)
    # Kept through the action: from the half-way yaw, still towards the chosen one.
    step, again = turn(pick, wrist + np.pi / 4 + 0.05, [0.45, 0.0, 0.2], 0.0, wrist)
    assert step == pytest.approx(-0.25) and again == wrist
    step, _ = turn(pick, wrist + 0.1, [0.45, 0.0, 0.2], -0.1, wrist)
    assert step == pytest.approx(-0.1)  # there: its own answer
    step, wrist = turn(place, np.pi / 2 + 0.1, [0.0, 0.45, 0.2], 0.0)
    assert step == pytest.approx(0.0) and wrist == pytest.approx(np.pi / 2 + 0.1)
    step, _ = turn(place, 0.1, [0.0, 0.45, 0.2], 0.0)
    assert step == pytest.approx(0.25)  # the same grasp turned a quarter, a step at a time
    whole = period(pick, cubes, RigidTransform([0.45, 0.0, 0.2]), max_turn=0.25)
    assert shaped(["keep_wrist_mid_range"], whole, move=[0, 0, 0, 0, 0, 0.05]).move[5] == 0.05


def test_a_far_destination_is_read_on_the_way_around_the_arms_base():
    """Towers on opposite sides of the table: the straight line between them passes 7 cm
    from the arm's base, where no top-down hand reaches. A destination further across
    than ``FAR_ACROSS`` reads as the point that far on the way around the base; walked
    step by step, the hand keeps to the towers' arc and arrives."""
    right, left = SLOTS[-2], SLOTS[-1]  # the outermost slots, either side
    assert np.hypot(*right) == pytest.approx(0.55) and right[1] * left[1] < 0
    (x0, y0), (x1, y1) = right, left
    assert abs(x0 * y1 - x1 * y0) / np.hypot(x1 - x0, y1 - y0) < 0.1  # the chord's nearest
    hand, steps = np.array(right), 0
    while not np.allclose(hand, left):
        ahead = around_base(hand, left, FAR_ACROSS)
        assert (
            np.hypot(*(ahead - hand)) == pytest.approx(FAR_ACROSS, abs=0.01)
            or (ahead == left).all()
        )
        assert np.hypot(*ahead) > 0.54  # on the arc, never across the base
        hand, steps = ahead, steps + 1
        assert steps < 20
    assert steps == int(np.ceil(0.55 * 2 * np.arctan2(abs(left[1]), left[0]) / FAR_ACROSS))

    # A pick's cube and target move by the same step; a place's held cube stays in the
    # hand; a near destination reads as it is, the same array.
    X_WG = RigidTransform([right[0], right[1], 0.3])
    far = np.zeros(SKILL_SIZE, np.float32)
    far[4:6] = far[8:10] = np.subtract(left, right)
    far[6], far[10] = -0.28, 0.0
    route = shield.STEPS["route_around_base"].run
    pick = SimpleNamespace(target=None)
    read = route(period(pick, {}, X_WG), far)
    ahead = around_base(right, left, FAR_ACROSS)
    np.testing.assert_allclose(read[4:6], ahead - right, atol=1e-6)
    np.testing.assert_allclose(read[8:10], ahead - right, atol=1e-6)
    np.testing.assert_array_equal(read[[6, 10]], far[[6, 10]])
    place = far.copy()
    place[4:7] = [0.0, 0.0, -0.012]
    read = route(period(SimpleNamespace(target=np.zeros(3)), {}, X_WG), place)
    np.testing.assert_array_equal(read[4:7], place[4:7])
    np.testing.assert_allclose(read[8:10], ahead - right, atol=1e-6)
    near = far.copy()
    near[4:6] = near[8:10] = [0.05, 0.05]
    assert route(period(pick, {}, X_WG), near) is near


def test_a_stopped_hand_takes_its_next_move_from_where_it_was_sent():
    """A stopped hand takes its next move from where it was last sent, at most
    ``CATCH_UP_M`` on; a moving hand, or the first period of an action, from where it is."""
    sent = np.array([0.5, 0.1, 0.2])
    hand = RigidTransform(sent - [0.004, 0.009, 0.0])

    def base(still_s, at=hand):
        p = period(None, {}, at, sent=sent, still_s=still_s)
        return shaped(["move_from_where_sent"], p).base.translation()

    np.testing.assert_allclose(base(0.1), sent)
    np.testing.assert_array_equal(base(0.0), hand.translation())  # moving, or just begun
    far = RigidTransform(sent - [0.0, 0.05, 0.0])
    np.testing.assert_allclose(base(0.1, far), far.translation() + [0.0, CATCH_UP_M, 0.0])


def _dz(action, cubes, hand, move, base=None, sent=None) -> float:
    """The move down or up the two height steps leave of ``move``."""
    at = hand if isinstance(hand, RigidTransform) else RigidTransform(hand)
    base = base or at
    sent = base.translation() if sent is None else sent
    p = period(action, cubes, at, sent=np.asarray(sent, float))
    names = ["cross_at_transit_height", "descend_only_over_target"]
    return float(shaped(names, p, move=[*move, 0, 0, 0], base=base).move[2])


def test_a_hand_goes_down_only_once_over_where_it_goes_down_to():
    """While more than ``OVER_M`` across from where it goes down to, a hand goes no lower
    than the classical pre-grasp height above it (``approach``), and a hand already lower
    goes no lower; over it, or going up, the skill's move is taken as it is."""
    approach = PARAMS.approach
    cube = np.array([0.565, -0.097, 0.06])  # the top of a two-cube tower
    cubes = {"b": RigidTransform(cube), "a": RigidTransform([0.47, -0.29, 0.02])}
    unstack = SimpleNamespace(cube="b", target=None, other="a")
    high = cube + [0.0, -0.042, 0.08]  # 4.2 cm across, 8 cm above
    assert _dz(unstack, cubes, high, [0, 0, -0.05]) == pytest.approx(approach - 0.08)
    assert _dz(unstack, cubes, cube + [0.0, -0.042, 0.041], [0, 0, -0.033]) == 0.0
    assert _dz(unstack, cubes, high, [0, 0, 0.02]) == 0.02  # going up
    over = cube + [OVER_M * 0.7, -OVER_M * 0.7, 0.041]
    assert _dz(unstack, cubes, over, [0, 0, -0.033]) == -0.033
    sent = RigidTransform(high + [0.0, 0.0, 0.02])  # a stopped hand's base, 2 cm above
    assert _dz(unstack, cubes, high, [0, 0, -0.05], sent) == pytest.approx(approach - 0.1)

    # A place: where the hand goes down to is the target, less the cube in the hand.
    target = np.array([0.47, -0.29, 0.06])  # onto "a"
    stack = SimpleNamespace(cube="b", target=target, other="a")
    off = np.array([0.003, -0.002, 0.001])  # the hand, from the cube in its fingers

    def holding(cube_at):
        cubes["b"] = RigidTransform(cube_at)
        return cube_at + off

    assert _dz(stack, cubes, holding(target + [0.2, 0.1, 0.2]), [0, 0, -0.05]) == -0.05
    low = holding(target + [0.03, 0.0, 0.07])
    assert _dz(stack, cubes, low, [0, 0, -0.03]) == pytest.approx(approach - 0.07)
    assert _dz(stack, cubes, holding(target + [0.005, 0.0, 0.07]), [0, 0, -0.03]) == -0.03


def test_a_crossing_hand_keeps_above_the_towers_beside_its_way():
    """While crossing, a hand keeps ``approach`` above every cube within
    ``BESIDE_WAY_M`` of its way this period, as well as above where it goes down to."""
    approach = PARAMS.approach
    top = np.array([0.541, -0.1, 0.18])  # a five-cube tower's top cube
    cubes = {
        "d": RigidTransform(top),
        "e": RigidTransform(top + [0.0, 0.12, -0.16]),  # on the table, 12 cm across
        "f": RigidTransform(top + [0.0, -0.21, -0.16]),  # on the table, the other side
    }
    hand = RigidTransform(top + [0.0, 0.0, 0.069])

    def down(move, at=hand, cube="e"):
        pick = SimpleNamespace(cube=cube, target=None, other=None)
        assert np.hypot(*(cubes[cube].translation() - at.translation())[:2]) < FAR_ACROSS
        return _dz(pick, cubes, at, move)

    assert down([0.007, 0.02, -0.033]) == pytest.approx(approach - 0.069)
    away = RigidTransform(top + [0.0, BESIDE_WAY_M + 0.01, 0.069])
    assert down([0.0, 0.02, -0.033], away) == -0.033
    beyond = RigidTransform(top + [0.0, -(BESIDE_WAY_M + 0.03), 0.069])
    assert down([0.0, -0.01, -0.033], beyond, "f") == -0.033
    low = RigidTransform(top + [0.0, 0.03, 0.03])
    assert down([0.0, 0.02, -0.02], low) == 0.0
    assert down([0.0, 0.02, 0.01], low) == 0.01


def test_a_hand_far_from_where_it_goes_down_to_keeps_to_the_transit_height():
    """Further than ``FAR_ACROSS`` across from where it goes down to, the hand keeps to
    the classical transit height of every cube but the one it holds, rising to it at
    most a step (5 cm) a period; going up, or above it, the skill's move is taken."""
    tower = np.array([0.5, 0.0, 0.02 + 7 * 0.04])  # an eight-cube tower's top cube
    held = np.array([0.5, 0.25, 0.30])  # a cube in the hand, 25 cm across from the tower
    cubes = {"h": RigidTransform(tower), "c": RigidTransform(held)}
    put = SimpleNamespace(cube="c", target=np.array([0.5, -0.2, 0.02]), other=None)
    transit = transit_height({"h": cubes["h"]}, None, PARAMS)
    assert transit == pytest.approx(tower[2] + 0.04 + PARAMS.transit_clearance)

    def down(hand_z, dz):
        return _dz(put, cubes, [0.5, 0.25, hand_z], [0.0, -0.03, dz])

    assert down(transit + 0.02, -0.05) == pytest.approx(-0.02)  # down to it, no lower
    assert down(transit - 0.08, -0.05) == pytest.approx(0.05)  # below: up a step a period
    assert down(transit - 0.01, -0.05) == pytest.approx(0.01)  # the last centimetre
    assert down(transit - 0.08, 0.05) == 0.05  # going up: as answered
    assert down(transit + 0.2, -0.05) == -0.05  # well above: as answered
    cubes["c"] = RigidTransform(tower + [0.0, -0.2, 0.04])  # a pick far off: not held
    pick = SimpleNamespace(cube="c", target=None, other=None)
    far = transit_height(cubes, None, PARAMS)
    assert _dz(pick, cubes, [0.5, 0.25, far], [0.0, -0.03, -0.05]) == 0.0


def test_a_held_back_hand_is_held_where_it_was_sent_and_a_put_down_is_over_half_a_cube():
    """A hand held back goes no lower than where it was last sent; a put-down's place, a
    free spot of the table, counts as under the hand within half a cube."""
    target = np.array([0.47, 0.27, 0.02])
    at = target + [0.015, -0.015, 0.045]  # 2.1 cm across, 4.5 cm up
    cubes = {"b": RigidTransform(at)}
    stack = SimpleNamespace(cube="b", target=target, other="a")
    put_down = SimpleNamespace(cube="b", target=target, other=None)
    hand = RigidTransform(at)
    assert _dz(stack, cubes, hand, [0, 0, -0.01]) == 0.0  # no lower than it is
    higher = at + [0, 0, 0.006]
    assert _dz(stack, cubes, hand, [0, 0, -0.01], sent=higher) == pytest.approx(0.006)
    assert _dz(stack, cubes, hand, [0, 0, -0.01], sent=at - [0, 0, 0.004]) == 0.0
    assert _dz(put_down, cubes, hand, [0, 0, -0.01]) == 0.0  # 2.1 cm: more than half a cube
    cubes["b"] = hand = RigidTransform(target + [0.012, -0.012, 0.045])  # 1.7 cm
    assert _dz(put_down, cubes, hand, [0, 0, -0.01]) == -0.01
    assert _dz(stack, cubes, hand, [0, 0, -0.01]) == 0.0


def _width(action, cube_at, hand_at, asked, fingers, stopped=False) -> float:
    cubes = {"e": RigidTransform(cube_at)}
    still = STILL_LET_GO_S if stopped else 0.0
    p = period(action, cubes, RigidTransform(hand_at), fingers=fingers, still_s=still)
    return shaped(GRIPPER, p, width=asked).width


def test_the_fingers_close_only_around_the_cube_and_open_only_where_it_rests():
    """A decision to close while the pick's cube is not between the fingers, or to open
    while the place's cube is in them and not resting on its target (a stack's within
    ``CENTRED`` across), is held at the fingers' present command."""
    target = np.array([0.16, -0.52, 0.10])
    stack = SimpleNamespace(cube="e", target=target, other="d")
    far = target + [0.15, 0.05, 0.05]
    w = lambda *a: _width(*a, fingers=0.04)  # noqa: E731
    assert w(stack, far, far + [0.002, 0.0, 0.001], 0.08) == 0.04  # held: 15 cm short
    assert w(stack, far, far, 0.02) == 0.02  # closing further is the skill's to say
    above = target + [0.0, 0.0, RESTING_M + 0.005]
    assert w(stack, above, above, 0.08) == 0.04  # over it, still 1.5 cm up
    seated = target + [0.003, 0.0, 0.002]
    assert w(stack, seated, seated, 0.08) == 0.08  # resting on it, 3 mm across: let go
    off = target + [CENTRED + 0.001, 0.0, 0.002]
    assert w(stack, off, off, 0.08) == 0.04  # off centre by more than CENTRED: held
    put = SimpleNamespace(cube="e", target=target, other=None)  # a put-down's free spot
    seated = target + [0.015, 0.0, 0.002]
    assert w(put, seated, seated, 0.08) == 0.08  # 1.5 cm across: as good
    off = target + [0.025, 0.0, 0.002]
    assert w(put, off, off, 0.08) == 0.04  # more than half a cube across
    assert w(stack, far, far + [0.0, 0.0, 0.06], 0.08) == 0.08  # not in the fingers

    unstack = SimpleNamespace(cube="e", target=None)
    top = np.array([0.541, -0.1, 0.38])  # a ten-cube tower's top cube
    home = top + [-0.078, 0.1, 0.023]
    w = lambda *a: _width(*a, fingers=0.08)  # noqa: E731
    assert w(unstack, top, home, 0.0) == 0.08  # 12 cm across: stays open
    assert w(unstack, top, top + [0.0, 0.0, 0.03], 0.0) == 0.08  # 3 cm over it
    assert w(unstack, top, top + [0.004, -0.003, 0.005], 0.0) == 0.0  # around it: closes
    assert w(unstack, top, home, 0.08) == 0.08  # opening is the skill's to say


def test_the_fingers_are_open_away_from_a_pick_s_cube_and_let_go_of_a_place_s():
    """Out of the fingers, a pick's cube is approached open and a place's, let go, is
    not closed on again; a place's hand stopped where its cube rests lets go."""
    cube = np.array([0.55, -0.08, 0.06])
    pick = SimpleNamespace(cube="e", target=None)
    assert _width(pick, cube, cube + [0.0, 0.0, 0.086], 0.0, 0.0) == GRIPPER_MAX  # 9 cm over
    assert _width(pick, cube, cube + [0.0, 0.0, 0.005], 0.0, 0.0) == 0.0  # around it

    spot = np.array([0.47, 0.28, 0.02])
    put = SimpleNamespace(cube="e", target=spot, other=None)
    assert _width(put, spot, spot + [0.0, 0.0, 0.05], 0.0, 0.08) == GRIPPER_MAX  # stays open
    rests = spot + [0.001, -0.006, 0.002]  # on the table, 6 mm from its spot
    assert _width(put, rests, rests, 0.0, 0.04) == 0.0  # moving: the skill's to say
    assert _width(put, rests, rests, 0.0, 0.04, stopped=True) == GRIPPER_MAX  # stopped
    above = spot + [0.0, 0.0, RESTING_M + 0.005]
    assert _width(put, above, above, 0.0, 0.04, stopped=True) == 0.0  # in the air: held


def test_a_place_s_hand_goes_back_up_clear_of_the_cube_it_placed():
    """Once the fingers have let go, the transit height a place reads is the classical
    retract's, clear of the placed cube, where the action's own is lower."""
    cube = np.array([0.164, -0.517, 0.26])
    cubes = {"g": RigidTransform(cube)}
    stack = SimpleNamespace(cube="g", target=cube)
    hand = RigidTransform(cube + [0.0, 0.0, 0.066])
    skill = np.zeros(13, np.float32)
    skill[12] = 0.31 - 0.326  # the action's transit height, 1.6 cm under the hand
    clear = shield.STEPS["retract_clear_of_placed"].run

    def read(width, action=stack):
        return clear(period(action, cubes, hand, width=width), skill)

    after = 0.26 + 0.04 + PARAMS.transit_clearance - 0.326
    assert read(0.08)[12] == pytest.approx(after)  # let go: up clear of the cube
    assert read(0.04)[12] == skill[12]  # still holding it: the action's own
    assert read(0.08, SimpleNamespace(cube="g", target=None))[12] == skill[12]  # a pick
    skill[12] = 0.2
    assert read(0.08)[12] == pytest.approx(0.2)  # the action's own is higher already


def _run(tmp_path, *settings):
    return subprocess.run(
        [sys.executable, "-m", "cake_drake.run", "--scenario",
         str(ROOT / "models/scenarios/learning.yaml"), "--name", "learned_tower5",
         "--no-render", "--out", str(tmp_path / "out"), *settings],
        capture_output=True, text=True, timeout=600, cwd=tmp_path,
    )  # fmt: skip


@pytest.mark.slow
def test_the_network_alone_runs_and_counts_no_step(tmp_path):
    """``motion.skill_rules: []``: the skill's network alone drives the hand; the run
    says so in its layers, and its summary counts no step."""
    r = _run(tmp_path, "--set", "motion.skill_rules=[]", "--set", "simulation.max_sim_s=6")
    assert r.returncode in (0, 3), r.stderr[-2000:]
    assert "the network alone, no shield" in r.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["layers"]["geometric"]["shield"] == []
    assert summary["skills"]["shield"] == {}
    assert summary["skills"]["steps"] > 0


def test_an_unknown_step_is_one_line_naming_the_valid_ones(tmp_path):
    r = _run(tmp_path, "--set", "motion.skill_rules=[limit_finger_speed, go_faster]")
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("error: ")
    assert "motion.skill_rules: no step 'go_faster'; the steps are end_try_when_still" in r.stderr
    assert not (tmp_path / "out").exists()
