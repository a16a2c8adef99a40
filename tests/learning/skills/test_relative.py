"""A skill that never sees the arm: what it reads does not move when the scene does; the
gripper is a decision (its loss and threshold by hand); its folder is checked before
anything runs, and a skill of the other kind is refused where this one is asked for.

The joint-space skill (models/policies/skills_joint_space) is the other kind; the
relative folders here are written by the trainer's own format (skill.json,
weights.npz) with small random weights.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from cake_drake.errors import InputError
from cake_drake.learning.skills import relative as rs
from cake_drake.policy.observations import (
    RELATIVE_SIZE,
    relative_vector,
    skill_context,
    skill_vector,
)
from cake_drake.symbolic import GroundAction
from cake_drake.world.scene import CUBE_SIZE, SLOTS
from tests.helpers import ROOT

JOINT_SKILL = ROOT / "models" / "policies" / "skills_joint_space"


def write_skill(folder: Path, hidden=(16, 16), n_obs: int = 2, last: int | None = None,
                gripper: dict | None = None, seed: int = 0) -> Path:  # fmt: skip
    """A relative skill's folder with random weights (``last``: the last layer's outputs)."""
    folder.mkdir(parents=True, exist_ok=True)
    meta = {
        "kind": rs.KIND, "format": rs.FORMAT, "input": rs.INPUT, "input_size": RELATIVE_SIZE,
        "n_obs_steps": n_obs, "hidden_dims": list(hidden), "moves": list(rs.MOVES),
        "gripper": gripper if gripper is not None else {"head": "closed_logit", "threshold": 0.7},
        "move_scale_m": 0.005,
    }  # fmt: skip
    (folder / "skill.json").write_text(json.dumps(meta))
    rng = np.random.default_rng(seed)
    width = RELATIVE_SIZE * n_obs
    arrays = {"in_mean": np.zeros(width), "in_std": np.ones(width),
              "move_mean": np.zeros(4), "move_std": np.full(4, 0.01)}  # fmt: skip
    sizes = [*hidden, last if last is not None else len(rs.MOVES) + 1]
    for k, n in enumerate(sizes):
        arrays[f"w{k}"] = rng.normal(0, 0.1, (width, n))
        arrays[f"b{k}"] = np.zeros(n)
        width = n
    np.savez(folder / "weights.npz", **arrays)
    return folder


# --- invariance ---------------------------------------------------------------------------

DOWN = RotationMatrix.MakeXRotation(np.pi)


def _scene(lift_cubes: int, shift_xy=(0.0, 0.0)):
    """Towers c-a (a on c) and d-b, a loose cube e, and the hand above a: the whole scene
    raised by ``lift_cubes`` whole cubes (on that many cubes under each tower and under e)
    and moved across the table by ``shift_xy``."""
    dz, (dx, dy) = lift_cubes * CUBE_SIZE, shift_xy
    yaw = RotationMatrix(RollPitchYaw(0.0, 0.0, 0.3))
    cubes = {}
    for name, (x, y, level, turn) in {
        "c": (0.50, 0.10, 0, False), "a": (0.501, 0.102, 1, True),
        "d": (0.45, -0.15, 0, False), "b": (0.452, -0.149, 1, False),
        "e": (0.35, 0.25, 0, True),
    }.items():  # fmt: skip
        z = CUBE_SIZE / 2 + level * CUBE_SIZE + dz
        cubes[name] = RigidTransform(yaw if turn else RotationMatrix(), [x + dx, y + dy, z])
    for k in range(lift_cubes):  # what the raised scene stands on
        for base, (x, y) in {"c": (0.50, 0.10), "d": (0.45, -0.15), "e": (0.35, 0.25)}.items():
            cubes[f"{base}{k}"] = RigidTransform([x + dx, y + dy, CUBE_SIZE / 2 + k * CUBE_SIZE])
    hand = RigidTransform(DOWN @ RotationMatrix.MakeZRotation(0.1),
                          [0.49 + dx, 0.11 + dy, 0.21 + dz])  # fmt: skip
    return cubes, hand


@pytest.mark.parametrize("action", [("unstack", ("a", "c")), ("stack", ("a", "b")),
                                    ("pick-up", ("e",))])  # fmt: skip
def test_the_scene_moved_up_by_whole_cubes_or_across_the_table_reads_the_same(action):
    action = GroundAction(*action)
    seen = []
    for lift, shift in ((0, (0.0, 0.0)), (3, (0.0, 0.0)), (6, (0.0, 0.0)), (2, (0.03, -0.04))):
        cubes, hand = _scene(lift, shift)
        ctx = skill_context(action, cubes, SLOTS)
        seen.append(relative_vector(skill_vector(ctx, cubes, hand), 0.08))
    for other in seen[1:]:
        # Number for number, to float32's last digits (the sums differ in their roundings).
        np.testing.assert_allclose(other, seen[0], rtol=0, atol=2e-7)
    # And what a joint-space skill reads does change: the arm reaches 24 cm higher.
    assert not np.allclose(_scene(6)[1].translation(), _scene(0)[1].translation())


# --- the gripper as a decision ------------------------------------------------------------


def test_the_gripper_decision_holds_between_its_thresholds():
    t = rs.THRESHOLD
    assert 0.5 < t < 1.0
    assert rs.decide(t + 0.01, last=False) is True  # past the threshold: close
    assert rs.decide(1 - t - 0.01, last=True) is False  # below 1 - threshold: open
    # Between the two, the last decision is held: a wavering answer does not flicker.
    assert rs.decide(0.55, last=False, threshold=0.7) is False
    assert rs.decide(0.45, last=True, threshold=0.7) is True
    assert rs.decide(0.55, last=None) is True and rs.decide(0.45, last=None) is False
    # A sequence that wavers around one half opens and closes once each.
    p = [0.1, 0.45, 0.55, 0.75, 0.52, 0.48, 0.6, 0.2, 0.55, 0.45]
    last, decisions = None, []
    for q in p:
        last = rs.decide(q, last, threshold=0.7)
        decisions.append(last)
    assert decisions == [False] * 3 + [True] * 4 + [False] * 3


def test_the_gripper_loss_is_the_binary_cross_entropy_by_hand():
    torch = pytest.importorskip("torch")
    from cake_drake.learning.skills.train_relative import losses

    logit = torch.tensor([2.0, -1.0, 0.0])
    closed = torch.tensor([1.0, 0.0, 1.0])
    moves = torch.tensor([[0.5, -0.5, 0.0, 1.0]])
    target = torch.tensor([[0.0, 0.0, 0.0, 0.0]])
    move, grip = losses(moves, logit, target, closed)
    # -[log s(2) + log(1 - s(-1)) + log s(0)] / 3, s the logistic function.
    s = lambda x: 1 / (1 + math.exp(-x))  # noqa: E731
    by_hand = -(math.log(s(2.0)) + math.log(1 - s(-1.0)) + math.log(s(0.0))) / 3
    assert grip.item() == pytest.approx(by_hand, rel=1e-6)
    assert move.item() == pytest.approx(0.5, rel=1e-6)  # (0.5 + 0.5 + 0 + 1) / 4


def test_a_skill_answers_a_hand_move_and_a_decided_gripper(tmp_path):
    skill = rs.RelativeSkill(write_skill(tmp_path / "s"))
    obs = {rs.INPUT: np.linspace(-0.1, 0.1, RELATIVE_SIZE)}
    answer = skill.act(obs)
    assert answer.shape == (7,) and np.all(np.isfinite(answer))
    assert answer[3] == 0.0 and answer[4] == 0.0  # no roll or pitch: the hand stays down
    assert answer[6] in (0.0, 1.0)
    # The NumPy forward is the network written: one layer by hand.
    w = np.load(tmp_path / "s" / "weights.npz")
    x = np.concatenate([obs[rs.INPUT]] * 2)
    h = rs.gelu(x @ w["w0"] + w["b0"])
    h = rs.gelu(h @ w["w1"] + w["b1"])
    out = h @ w["w2"] + w["b2"]
    moves, p = skill.forward(x[None])
    np.testing.assert_allclose(moves[0, :3], rs.expand(out[:3] * 0.01, 0.005))  # format 3
    assert moves[0, 3] == pytest.approx(out[3] * 0.01)
    assert p[0] == pytest.approx(1 / (1 + np.exp(-out[4])))


def test_a_pick_aims_the_hand_and_a_place_aims_the_held_cube():
    """The move onto the target: a pick's is the hand's onto the point above its cube; a
    place's is the held cube's onto where it rests, however the cube sits in the hand."""
    v = np.zeros(RELATIVE_SIZE)
    v[4:7] = [0.0, 0.0, -0.012]  # the cube 12 mm below the grasp frame
    v[7], v[8:11], v[11] = 0.1, [0.05, -0.02, -0.10], 0.3
    v[1] = 1.0  # unstack
    np.testing.assert_allclose(rs.target_from_hand(v), [0.05, -0.02, -0.10, 0.1])
    v[1], v[3] = 0.0, 1.0  # stack
    np.testing.assert_allclose(rs.target_from_hand(v), [0.05, -0.02, -0.088, 0.2])
    # Once the fingers have let go, the hand goes up over the place to the transit height
    # (12): a target that holds still, where the released cube (format 1's) is no target.
    v[12], v[rs.WIDTH] = 0.22, 0.08
    np.testing.assert_allclose(rs.target_from_hand(v), [0.05, -0.02, 0.22, 0.2])
    np.testing.assert_allclose(rs.target_from_hand(v, up_after_release=False),
                               [0.05, -0.02, -0.088, 0.2])  # fmt: skip


def test_a_format_1_skill_is_acted_as_it_was_trained(tmp_path):
    folder = write_skill(tmp_path / "s")
    assert rs.RelativeSkill(folder).up_after_release
    meta = json.loads((folder / "skill.json").read_text())
    (folder / "skill.json").write_text(json.dumps({**meta, "format": 1}))
    assert not rs.RelativeSkill(folder).up_after_release
    (folder / "skill.json").write_text(json.dumps({**meta, "format": 2}))
    assert rs.RelativeSkill(folder).move_scale is None  # format 2: moves as they are
    (folder / "skill.json").write_text(json.dumps({**meta, "format": 3}))
    assert not rs.RelativeSkill(folder).format4  # format 3: the transit height as read
    assert rs.RelativeSkill(write_skill(tmp_path / "t")).format4
    (folder / "skill.json").write_text(json.dumps({**meta, "format": 5}))
    with pytest.raises(
        InputError, match=r"skill.json: field .format. is 5; this version reads 1 or 2 or 3 or 4"
    ):
        rs.RelativeSkill(folder)
    (folder / "skill.json").write_text(json.dumps({**meta, "move_scale_m": "5 mm"}))
    with pytest.raises(InputError, match=r"skill.json: move_scale_m '5 mm'; a skill of "
                                         r"format 3 or later"):  # fmt: skip
        rs.RelativeSkill(folder)


def test_a_hand_above_its_transit_height_reads_as_a_hand_at_it(tmp_path):
    """Format 4: a put-down begun above its transit height (the unstack before it took
    the tallest tower's top cube, and the transit height dropped by a cube) reads, to the
    network, as a put-down at its transit height; below it, as it is."""
    v = np.zeros(RELATIVE_SIZE)
    v[2], v[4:7], v[8:11], v[12], v[rs.WIDTH] = 1.0, [0, 0, -0.02], [0.1, 0.05, -0.18], -0.04, 0.04
    read = rs.floor_transit(v)
    assert read[12] == 0.0 and np.array_equal(np.delete(read, 12), np.delete(v, 12))
    assert v[12] == -0.04  # a copy
    two = rs.floor_transit(np.concatenate([v, np.r_[v[:12], 0.05, v[13:]]]))
    assert two[12] == 0.0 and two[RELATIVE_SIZE + 12] == 0.05  # each observation alike
    # The skill reads it so (its network's input is what it reads)...
    skill = rs.RelativeSkill(write_skill(tmp_path / "s"))
    above, at = skill.forward(np.r_[v, v][None]), skill.forward(np.r_[read, read][None])
    first = skill.act({rs.INPUT: v})
    np.testing.assert_array_equal(skill._seen[-1], read)
    assert not np.array_equal(above[0], at[0])  # the floor is no no-op for a network
    np.testing.assert_allclose(first[[0, 1, 2, 5]], at[0][0] + rs.target_from_hand(v))
    # A format-3 skill reads the transit height as it comes.
    meta = json.loads((tmp_path / "s" / "skill.json").read_text())
    (tmp_path / "s" / "skill.json").write_text(json.dumps({**meta, "format": 3}))
    old = rs.RelativeSkill(tmp_path / "s")
    old.act({rs.INPUT: v})
    np.testing.assert_array_equal(old._seen[-1], v)


def test_a_format_3_skill_answers_its_moves_finely_near_the_target(tmp_path):
    """Format 3 learns and answers the moves on a scale that is fine near the target and
    coarse far from it; the network's answer comes back to metres exactly."""
    moves = np.array([-0.3, -0.01, -0.001, 0.0, 0.0005, 0.001, 0.01, 0.3])
    scaled = rs.compress(moves, 0.005)
    np.testing.assert_allclose(rs.expand(scaled, 0.005), moves, atol=1e-15)
    assert np.all(np.diff(scaled) > 0) and scaled[3] == 0.0
    # a move at the target spans 21 times what it spans 10 cm out
    at = lambda m: rs.compress(np.array([m + 1e-6]), 0.005) - rs.compress(np.array([m]), 0.005)  # noqa: E731
    assert at(0.0)[0] / at(0.1)[0] == pytest.approx(21.0, rel=0.05)
    skill = rs.RelativeSkill(write_skill(tmp_path / "s"))
    assert skill.move_scale == 0.005
    x = np.zeros((1, 2 * RELATIVE_SIZE))
    skill.move_scale = None
    raw, p = skill.forward(x)
    skill.move_scale = 0.005
    moved, q = skill.forward(x)
    np.testing.assert_allclose(moved[:, :3], rs.expand(raw[:, :3], 0.005))
    assert moved[0, 3] == raw[0, 3] and p[0] == q[0]  # the yaw and the gripper as they were


def _pick_recording():
    """One demonstrated pick-up, as the recording's columns: the hand crosses at the
    transit height to over its cube (frames 0-9, 1 cm a frame), goes down (10-19, 2 cm a
    frame), closes (20-24); each frame's command is the move to the next frame's hand."""
    n = 25
    hand = np.zeros((n, 3))
    hand[:10, 0] = np.arange(-0.10, 0.0, 0.01)
    hand[10:20, 2] = -0.02 * np.arange(10)
    hand[20:] = hand[19]
    skill = np.zeros((n, 13))
    skill[:, 0] = 1.0  # pick-up
    skill[:, 4:7] = np.array([0.0, 0.0, -0.2]) - hand  # the cube, 20 cm under the transit
    skill[:, 8:11] = -hand  # the target: over the cube at the transit height
    skill[:, 12] = -hand[:, 2]
    action = np.zeros((n, 7))
    action[:-1, :3] = hand[1:] - hand[:-1]
    action[:, 6] = np.r_[np.ones(20), np.zeros(5)]  # open, then closed
    return {
        "skill": skill, "width": np.full(n, 0.08), "action": action,
        "ground": np.tile([0, 0, -1, 0], (n, 1)), "episode": np.zeros(n, int),
        "frame": np.arange(n), "fps": np.float64(10.0),
    }  # fmt: skip


def test_a_hand_still_crossing_learns_to_come_over_its_target_before_going_down():
    """The heading half a second on, but no further than where the hand comes over its
    target: a crossing frame is taught the point over the cube, not the descent after
    it (a corner cut brings open fingers down beside a tower's top cube)."""
    from cake_drake.learning.skills import train_relative as training

    x, moves, closed = training.examples(_pick_recording(), 1, lookahead=5)
    assert x.shape == (25, RELATIVE_SIZE) and moves.shape == (25, 4)
    # Frame 7, 3 cm short: five frames on would be 4 cm down the descent (frame 12's
    # command from the target: -0.06); it is taught the frame it comes over (10), whose
    # command is the first 2 cm down.
    np.testing.assert_allclose(moves[7, :3], [0.0, 0.0, -0.02], atol=1e-12)
    # Frame 3: five frames on is still crossing (frame 8, a centimetre short): no cap.
    np.testing.assert_allclose(moves[3, :3], [-0.01, 0.0, 0.0], atol=1e-12)
    # Over it, the heading looks five frames on down the descent, to the gripper's change.
    np.testing.assert_allclose(moves[11, :3], [0.0, 0.0, -0.14], atol=1e-12)
    np.testing.assert_allclose(moves[17, :3], moves[19, :3], atol=1e-12)  # the closing
    assert closed[:19].sum() == 0 and closed[20:].all()


def test_training_varies_only_what_leaves_the_answer_where_it_was():
    """The trainer's augmentation moves the hand about a held cube and a descending
    hand's transit height, and changes the label only as much as keeps the answer in the
    world the same: the held cube set where it was set, the hand sent where it was sent."""
    from cake_drake.learning.skills import train_relative as training

    place = np.zeros(RELATIVE_SIZE)
    place[3], place[4:7], place[7] = 1.0, [0.001, -0.002, -0.001], 0.05  # stack, held
    place[8:11], place[11], place[12], place[13] = [0.001, 0.0005, -0.03], 0.02, 0.2, 0.04
    descent = np.zeros(RELATIVE_SIZE)  # a pick going down onto its cube
    descent[0], descent[4:7], descent[13] = 1.0, [0.001, 0.0, -0.12], 0.08
    descent[8:11], descent[12] = [0.001, 0.0, 0.15], 0.15  # above the cube, at transit
    crossing, at_transit = descent.copy(), descent.copy()
    crossing[8:10] = [0.05, 0.02]  # not over its cube yet: how high it goes matters
    at_transit[10] = at_transit[12] = 0.004  # level with the transit height
    kinds = [place, descent, crossing, at_transit]
    x = np.concatenate([np.tile(np.r_[v, v], (300, 1)) for v in kinds])  # n_obs 2
    moves = np.tile([0.002, -0.001, 0.004, 0.01], (len(x), 1))
    x2, moves2 = training.augment(x, moves, np.random.default_rng(1))
    assert np.array_equal(x[:, :14], x[:, 14:]) and np.array_equal(x2[:, :14], x2[:, 14:])
    now, now2 = x[:, 14:], x2[:, 14:]
    changed = np.any(x2 != x, axis=1)
    rows = np.arange(len(x)) // 300
    for k in (0, 1):  # about half of each varied; the others not at all
        assert 0.35 < changed[rows == k].mean() < 0.65
    assert not changed[rows >= 2].any() and np.array_equal(moves2[rows >= 2], moves[rows >= 2])
    # The place: the hand moved about the held cube by up to GRASP_JITTER, the cube where
    # it was in the world: its rest read from the hand moved alike, the cube as far
    # from its rest as it was (so its release is decided alike), and it is set where it
    # was set, from its rest (the hand's move + the cube in the hand - the rest).
    p = rows == 0
    shift = now2[p, 4:8] - now[p, 4:8]
    assert np.abs(shift).max() <= training.GRASP_JITTER.max()
    assert np.abs(shift[:, 2]).max() > 0.008
    np.testing.assert_allclose(now2[p, 8:12] - now[p, 8:12], shift, atol=1e-12)
    from_rest = lambda v, m: rs.target_from_hand(v)[:, :3] + m[:, :3] + v[:, 4:7] - v[:, 8:11]  # noqa: E731
    np.testing.assert_allclose(
        from_rest(now2[p], moves2[p]), from_rest(now[p], moves[p]), atol=1e-12
    )
    np.testing.assert_array_equal(moves2[p], moves[p])
    # The descent: the transit height anywhere from TRANSIT_CLEAR above the hand up; the
    # pick's target rose with it and its move fell as much: the hand goes where it went.
    d = rows == 1
    assert now2[d, 12].min() >= training.TRANSIT_CLEAR - 1e-12
    assert now2[d, 12].max() > 0.3 and now2[d, 12].min() < 0.1
    np.testing.assert_allclose(now2[d, 10] - now2[d, 12], now[d, 10] - now[d, 12])
    sent = lambda v, m: rs.target_from_hand(v) + m  # noqa: E731
    np.testing.assert_allclose(sent(now2[d], moves2[d]), sent(now[d], moves[d]), atol=1e-12)


def test_the_hand_keeps_to_its_target_while_the_fingers_move(tmp_path):
    """When the gripper's decision changes, the hand keeps to where it was headed (the
    cube it grasps) until the fingers stop: no lift before the grip."""
    skill = rs.RelativeSkill(write_skill(tmp_path / "s"))
    v = np.zeros(RELATIVE_SIZE)
    v[0], v[13] = 1.0, 0.08
    decisions = iter([0.1, 0.9, 0.9, 0.9, 0.9, 0.9])
    widths = iter([0.08, 0.08, 0.06, 0.045, 0.04, 0.04])
    answers, headed = [], []
    skill.forward = lambda x: (np.array([[0.001 * len(answers), 0, 0, 0]]),
                               np.array([next(decisions)]))  # fmt: skip
    for _ in range(6):
        v[13] = next(widths)
        answers.append(skill.act({rs.INPUT: v.copy()}))
        headed.append(answers[-1][0])
    assert [a[6] for a in answers] == [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    # Steps 1-4: the fingers close, the hand keeps step 0's heading; step 5: they are still.
    assert headed[:5] == [0.0] * 5 and headed[5] == pytest.approx(0.005)


def test_a_hand_stopped_with_its_probability_between_the_thresholds_decides_the_nearer_side(
    tmp_path,
):
    """The band between the thresholds holds the last decision while the hand moves; a
    hand that stays where it is for ``STOPPED_STEPS`` decides by the nearer side, so it
    does not hover over its place with the cube held until its budget runs out."""
    skill = rs.RelativeSkill(write_skill(tmp_path / "s"))
    v = np.zeros(RELATIVE_SIZE)
    v[3], v[10], v[13] = 1.0, -0.002, 0.039  # a stack, the cube held 2 mm over its rest
    probabilities = iter([0.9] + [0.45] * 30)
    skill.forward = lambda x: (np.zeros((1, 4)), np.array([next(probabilities)]))
    moving = [skill.act({rs.INPUT: v.copy()})[6]]
    for k in range(4):  # the hand still coming down: the decision held, closed
        v[10] += 0.001 * (k % 2 * 2 - 1)
        moving.append(skill.act({rs.INPUT: v.copy()})[6])
    assert moving == [0.0] * 5
    stopped = [skill.act({rs.INPUT: v.copy()})[6] for _ in range(rs.STOPPED_STEPS + 1)]
    assert stopped[: rs.STOPPED_STEPS - 1] == [0.0] * (rs.STOPPED_STEPS - 1)
    assert stopped[-1] == 1.0  # stopped, 0.45 is nearer open: let go


# --- folders checked before anything runs -------------------------------------------------


@pytest.mark.parametrize(
    "damage, said",
    [
        ({"last": 4}, "the last layer answers 4 numbers; a skill answers 4 moves"),
        ({"last": 7}, "the last layer answers 7 numbers"),
        ({"gripper": {}}, "no gripper head (gripper.head: closed_logit"),
        ({"gripper": {"head": "closed_logit", "threshold": 0.3}}, "gripper.threshold 0.3"),
    ],
)
def test_a_skill_whose_gripper_head_is_missing_or_of_another_size_is_one_line(
    tmp_path, damage, said
):
    folder = write_skill(tmp_path / "s", **damage)
    with pytest.raises(InputError, match=said.replace("(", r"\(")):
        rs.check_folder(folder)


def test_numbers_that_are_not_finite_are_refused(tmp_path):
    folder = write_skill(tmp_path / "s")
    w = dict(np.load(folder / "weights.npz"))
    w["w1"][0, 0] = np.nan
    np.savez(folder / "weights.npz", **w)
    with pytest.raises(InputError, match="w1 holds numbers that are not finite"):
        rs.check_folder(folder)


def _run(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cake_drake.run", *args], cwd=cwd, capture_output=True,
        text=True, timeout=300, env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip


@pytest.mark.parametrize(
    "skills, space, said",
    [
        (JOINT_SKILL, "relative", "a skill that reads the arm's joints (a LeRobot checkpoint), "
         "run as motion.skill_action_space: relative"),
        (None, "joint_position", "a skill that never sees the arm (skill.json: hand moves, "
         "the gripper decided), run as motion.skill_action_space: joint_position"),
        (None, "ee_delta", "run as motion.skill_action_space: ee_delta"),
    ],
)  # fmt: skip
def test_a_skill_of_the_other_kind_is_refused_before_simulating(tmp_path, skills, space, said):
    pytest.importorskip("lerobot")
    folder = skills or write_skill(tmp_path / "rel")
    scenario = tmp_path / "s.yaml"
    scenario.write_text(
        's:\n  task: {problem: "package://cake_drake/pddl/stack2.pddl"}\n'
        f'  motion: {{skills: "{folder}", skill_action_space: {space}}}\n'
    )
    r = _run(
        "--scenario", str(scenario), "--name", "s", "--out", str(tmp_path / "out"), cwd=tmp_path
    )
    assert r.returncode == 2, r.stderr
    assert said in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()  # refused before anything was written


def test_a_mass_range_is_drawn_per_seed_and_checked():
    from cake_drake.pipeline import check
    from cake_drake.scenario import Scenario
    from cake_drake.world.scene import WorldConfig, cube_mass

    w = WorldConfig(cube_mass_range_kg=[0.05, 0.5])
    masses = [cube_mass(w, seed) for seed in range(200)]
    assert all(0.05 <= m <= 0.5 for m in masses) and len(set(masses)) == 200
    assert cube_mass(w, 7) == cube_mass(w, 7)  # the same seed, the same mass
    assert min(masses) < 0.1 and max(masses) > 0.45  # the whole range is drawn
    assert cube_mass(WorldConfig(cube_mass_kg=0.2), 3) == 0.2
    for bad, said in (([0.5, 0.05], "lo above hi"), ([0.05], "give two"),
                      ([0.05, 2.0], "outside 0.01 to 1")):  # fmt: skip
        s = Scenario()
        s.task.problem = "package://cake_drake/pddl/stack2.pddl"
        s.world.cube_mass_range_kg = bad
        with pytest.raises(InputError, match=said):
            check(s, write=False)


def test_a_damaged_recording_is_one_line_naming_its_file(tmp_path):
    pytest.importorskip("pyarrow")
    from cake_drake.learning.skills.train_relative import read_frames

    (tmp_path / "meta").mkdir()
    (tmp_path / "meta" / "info.json").write_text('{"fps": 10}')
    data = tmp_path / "data" / "chunk-000"
    data.mkdir(parents=True)
    (data / "file-000.parquet").write_bytes(b"PAR1" + b"\0" * 100)  # cut short
    with pytest.raises(InputError, match="file-000.parquet: not a readable Parquet table"):
        read_frames(tmp_path)
    (tmp_path / "meta" / "info.json").write_text('{"fps": "ten"')
    with pytest.raises(InputError, match="info.json: no recording's info"):
        read_frames(tmp_path)


def test_a_learning_tasks_episodes_carry_its_cubes_mass():
    """A task's episodes are of its world: one mass (``learned_cake``'s 0.5 kg) or a range."""
    pytest.importorskip("gymnasium")
    from cake_drake.learning.data.recording import spec_from_scenario
    from cake_drake.scenario import load_scenario

    suite = ROOT / "models" / "scenarios" / "learning.yaml"
    assert spec_from_scenario(load_scenario(suite, "learned_cake")).cube_mass_range_kg == (0.5, 0.5)
    assert spec_from_scenario(load_scenario(suite, "skills_relative")).cube_mass_range_kg == (
        0.05, 0.5)  # fmt: skip
    assert spec_from_scenario(load_scenario(suite, "tower5")).cube_mass_range_kg == ()


def test_a_far_target_reads_as_a_near_one_in_its_direction(tmp_path):
    """Format 4: a target further across than FAR_ACROSS reads as if the hand were that far from it
    on the line to it: two hands 40 cm and 70 cm from the same cube read the same
    numbers; what the fingers hold moves with the hand, a cube still to be picked does
    not; the skill's answer is then a heading near its target, and its move is taken
    from where the hand really is."""
    pick = np.zeros(RELATIVE_SIZE)
    pick[0], pick[rs.WIDTH] = 1.0, 0.08  # a pick, fingers open
    reads = []
    for far in (0.4, 0.7):
        v = pick.copy()
        v[4:7], v[8:11], v[12] = [far * 0.6, far * 0.8, -0.09], [far * 0.6, far * 0.8, 0.0], 0.0
        reads.append(rs.near_target(v))
    np.testing.assert_allclose(reads[0], reads[1], atol=1e-12)
    np.testing.assert_allclose(reads[0][8:11], [rs.FAR_ACROSS * 0.6, rs.FAR_ACROSS * 0.8, 0.0])
    np.testing.assert_allclose(reads[0][4:7], [rs.FAR_ACROSS * 0.6, rs.FAR_ACROSS * 0.8, -0.09])
    near = pick.copy()
    near[4:6] = near[8:10] = [0.03, 0.04]
    np.testing.assert_array_equal(rs.near_target(near), near)  # within FAR_ACROSS: as it is
    # A place: the held cube, 12 mm below the grasp frame, stays where it is in the hand.
    place = np.zeros(RELATIVE_SIZE)
    place[2], place[rs.WIDTH] = 1.0, 0.04
    place[4:7], place[8:11] = [0.0, 0.0, -0.012], [0.0, -0.5, -0.2]
    read = rs.near_target(place)
    np.testing.assert_allclose(read[4:7], place[4:7])
    np.testing.assert_allclose(read[8:11], [0.0, -rs.FAR_ACROSS, -0.2])
    # In a run: the network answers from what it reads; the move from the real hand.
    skill = rs.RelativeSkill(write_skill(tmp_path / "s"))
    moves, _ = skill.forward(np.r_[read, read][None])
    answer = skill.act({rs.INPUT: place})
    np.testing.assert_allclose(answer[[0, 1, 2, 5]], moves[0] + rs.target_from_hand(place))


def test_a_place_far_below_reads_as_one_deep_below():
    """Format 4: a held cube's place further below it than DEEP reads as DEEP below (a
    put-down 32 cm below the top of a ten-cube tower was answered with a move up); the
    held cube stays in the hand, a place within DEEP and a pick's cube far below read as
    they are, and so does a place once the fingers have let go."""
    place = np.zeros(RELATIVE_SIZE)
    place[2], place[rs.WIDTH] = 1.0, 0.04  # a put-down, the cube in the fingers
    place[4:7], place[8:11] = [0.0, 0.0, -0.012], [0.03, 0.0, -0.332]
    read = rs.near_target(place)
    np.testing.assert_allclose(read[4:7], place[4:7])
    np.testing.assert_allclose(read[8:11], [0.03, 0.0, -0.012 - rs.DEEP])
    np.testing.assert_allclose(rs.target_from_hand(read)[2], -rs.DEEP)
    within = place.copy()
    within[10] = -0.15
    np.testing.assert_array_equal(rs.near_target(within), within)
    let_go = place.copy()
    let_go[rs.WIDTH] = 0.08
    np.testing.assert_array_equal(rs.near_target(let_go)[8:11], let_go[8:11])
    pick = np.zeros(RELATIVE_SIZE)
    pick[0], pick[rs.WIDTH] = 1.0, 0.08
    pick[4:7], pick[8:11] = [0.02, 0.0, -0.4], [0.02, 0.0, 0.0]
    np.testing.assert_array_equal(rs.near_target(pick), pick)
