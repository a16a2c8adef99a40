"""The learned planner: a network in the planner registry, for any number of blocks."""

from __future__ import annotations

import json
import random
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from cake_drake.errors import InputError, NoPlanError
from cake_drake.learning.training.planner import PlannerRecipe, Space, export, samples
from cake_drake.symbolic import (
    BLOCKSWORLD_DOMAIN,
    NAMINGS,
    PROBLEM_5,
    load_domain,
    load_problem,
    parse_problem,
    random_problem,
    solve_problem,
    validate_plan,
)
from cake_drake.symbolic.learned import SHIPPED, load_planner, read_problem, weight_shapes
from tests.helpers import DATA, ROOT


def _cli(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=600)  # fmt: skip


def _optimal_length(problem) -> int:
    _, graph = read_problem(problem)
    space = Space(len(graph.below))
    return int(space.distances(graph)[space.index[graph.below]])


def test_the_shipped_planner_plans_problem_5_optimally():
    problem = load_problem(BLOCKSWORLD_DOMAIN, PROBLEM_5)
    plan = solve_problem(problem, "learned")
    assert plan.length == 10 == _optimal_length(problem)
    assert validate_plan(problem, plan.actions).ok
    assert plan.planner == "learned" and not plan.optimal
    assert "relational network" in plan.heuristic and "planners/blocks" in plan.heuristic


@pytest.mark.parametrize("style", ["exercise", "ipc", "typed"])
def test_the_shipped_planner_plans_a_generated_12_block_problem_validly(style):
    naming = NAMINGS[style]
    text = random_problem(12, 7, naming, partial=style != "exercise")
    problem = parse_problem(load_domain(naming.domain_file), text)
    plan = solve_problem(problem, "learned")
    assert validate_plan(problem, plan.actions).ok
    assert plan.length <= 4 * 12  # never more than moving every block twice


def test_it_is_invariant_to_renaming_and_reordering_the_blocks():
    text = PROBLEM_5.read_text()
    problem = load_problem(BLOCKSWORLD_DOMAIN, PROBLEM_5)
    plan = solve_problem(problem, "learned")
    names = sorted(problem.objects)
    shuffled = names[:]
    random.Random(3).shuffle(shuffled)
    rename = {a: f"cube-{b}" for a, b in zip(names, shuffled, strict=True)}
    # Rename every block (one pass, so no name is renamed twice), and list the
    # objects in another order.
    renamed = re.sub(r"\b([a-e])\b(?=[ )])", lambda m: rename[m.group(1)], text)
    objects = "(:objects " + " ".join(sorted(rename.values(), reverse=True)) + ")"
    renamed = re.sub(r"\(:objects[^)]*\)", objects, renamed)
    other = parse_problem(load_domain(BLOCKSWORLD_DOMAIN), renamed)
    assert set(other.objects) == set(rename.values())
    got = solve_problem(other, "learned")
    expected = [(a.name, tuple(rename[x] for x in a.args)) for a in plan.actions]
    assert [(a.name, a.args) for a in got.actions] == expected


def test_a_few_training_steps_write_a_checkpoint_that_plan_loads(tmp_path):
    out = tmp_path / "tiny"
    r = _cli("cake_drake.train", "--planner", "--out", str(out), "--steps", "20",
             "--blocks", "3", "4")  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert f"plan with --planner learned@{out}" in r.stdout
    assert {p.name for p in out.iterdir()} >= {"planner.json", "weights.npz"}
    cfg = json.loads((out / "planner.json").read_text())
    assert cfg["kind"] == "cake_drake.learned_planner" and cfg["training"]["blocks"] == [3, 4]
    r = _cli("cake_drake.plan", "--planner", f"learned@{out}")
    # Twenty steps may or may not have learned problem_5: either a valid plan or the
    # planners' "no plan" exit naming why the rollout stopped, never a wrong plan.
    assert r.returncode in (0, 1), r.stderr
    if r.returncode == 0:
        assert f"planner learned@{out}" in r.stdout
    else:
        assert "the learned planner" in r.stderr and "gave up" in r.stderr


def test_the_planner_is_written_into_plan_txt_and_the_plan_command_names_it(tmp_path):
    r = _cli("cake_drake.plan", "--planner", "learned", "--output", str(tmp_path / "plan.txt"))
    assert r.returncode == 0, r.stderr
    text = (tmp_path / "plan.txt").read_text()
    assert "; planner: learned (satisficing" in text
    assert "relational network" in text


def _damaged(tmp_path: Path, how: str) -> Path:
    folder = tmp_path / how
    if how == "missing":
        return folder
    folder.mkdir()
    if how == "empty":
        return folder
    shutil.copy(SHIPPED / "planner.json", folder)
    shutil.copy(SHIPPED / "weights.npz", folder)
    weights = folder / "weights.npz"
    cfg = folder / "planner.json"
    if how == "truncated":
        weights.write_bytes(weights.read_bytes()[:300])
    elif how == "not json":
        cfg.write_text('{"kind": "cake_drake.learned_planner", ')
    elif how == "not a mapping":
        cfg.write_text("[1, 2]")
    elif how == "other kind":
        cfg.write_text(json.dumps({**json.loads(cfg.read_text()), "kind": "a policy"}))
    elif how == "other width":
        data = json.loads(cfg.read_text())
        data["architecture"]["width"] = 32
        cfg.write_text(json.dumps(data))
    elif how == "nan":
        w = dict(np.load(weights))
        w["enc_w"][0, 0] = np.nan
        np.savez(weights, **w)
    elif how == "missing array":
        w = dict(np.load(weights))
        del w["bi_p"]
        np.savez(weights, **w)
    return folder


@pytest.mark.parametrize(
    "how, words",
    [
        ("missing", "no such folder; a learned planner checkpoint is a folder of planner.json"),
        ("empty", "planner.json is missing"),
        ("truncated", "weights.npz: not a learned planner checkpoint: not a readable .npz"),
        ("not json", "planner.json: not a learned planner checkpoint: unreadable JSON (line 1)"),
        ("not a mapping", "holds a list, not a mapping"),
        ("other kind", "field 'kind' is 'a policy'"),
        ("other width", "array enc_w has shape (10, 64), but planner.json asks for (10, 32)"),
        ("nan", "array enc_w holds NaN"),
        ("missing array", "missing bi_p"),
    ],
)
def test_a_damaged_checkpoint_is_one_line_and_exit_2_before_anything_runs(tmp_path, how, words):
    folder = _damaged(tmp_path, how)
    with pytest.raises(InputError) as e:
        load_planner(folder)
    assert words in str(e.value)
    r = _cli("cake_drake.run", "--planner", f"learned@{folder}", "--no-render", "--quiet",
             "--out", str(tmp_path / "out"))  # fmt: skip
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and words in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "out").exists()


def _refused_unread(tmp_path: Path, how: str) -> Path:
    folder = tmp_path / how.replace(" ", "_")
    folder.mkdir()
    shutil.copy(SHIPPED / "planner.json", folder)
    shutil.copy(SHIPPED / "weights.npz", folder)
    weights, cfg = folder / "weights.npz", folder / "planner.json"
    if how == "structured":
        w = dict(np.load(weights))
        w["enc_b"] = np.zeros(w["enc_b"].shape, dtype=[("x", "<f8"), ("y", "<f8")])
        np.savez(weights, **w)
    elif how == "hidden huge array":
        # A few bytes whose npy header claims 1 GiB: refused by its header, so nothing
        # is decompressed (np.load would allocate it and read on).
        with zipfile.ZipFile(weights, "a", zipfile.ZIP_DEFLATED) as z, z.open("junk.npy", "w") as f:
            header = {"descr": "<f8", "fortran_order": False, "shape": (2**27,)}
            np.lib.format.write_array_header_1_0(f, header)
            f.write(b"\0" * 64)
    elif how == "large json":
        # Valid JSON (the shipped file and 17 MiB of spaces), over the inputs' limit.
        cfg.write_text(cfg.read_text() + " " * (17 * 2**20))
    return folder


NOT_A_CHECKPOINT = "not a learned planner checkpoint: "


@pytest.mark.parametrize(
    "how, words",
    [
        ("structured", f"weights.npz: {NOT_A_CHECKPOINT}array 'enc_b' must hold numbers"),
        (
            "hidden huge array",
            f"weights.npz: {NOT_A_CHECKPOINT}its arrays hold more than 256 MiB "
            "('junk' has shape (134217728,))",
        ),
        ("large json", f"planner.json: {NOT_A_CHECKPOINT}18 MB is too large (at most 16 MiB)"),
    ],
)
def test_a_checkpoint_is_read_by_the_checked_reader_and_refused_unread(tmp_path, how, words):
    # weights.npz goes through cake_drake.formats.read_npz (every array by its header
    # before anything is decompressed); planner.json over 16 MiB is refused unread.
    folder = _refused_unread(tmp_path, how)
    with pytest.raises(InputError) as e:
        load_planner(folder)
    assert words in str(e.value)
    r = _cli("cake_drake.plan", "--planner", f"learned@{folder}")
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and words in r.stderr and "Traceback" not in r.stderr


def test_a_domain_the_network_cannot_read_is_named(tmp_path):
    r = _cli("cake_drake.plan", str(DATA / "blocks_paint.pddl"), str(PROBLEM_5),
             "--planner", "learned")  # fmt: skip
    assert r.returncode == 2
    assert "blocks_paint.pddl" in r.stderr and "Traceback" not in r.stderr


def test_a_problem_with_objects_that_are_not_blocks_is_named(tmp_path):
    domain = tmp_path / "domain.pddl"
    domain.write_text(
        (ROOT / "models/pddl/variants/blocksworld-typed.pddl")
        .read_text()
        .replace("(:types block)", "(:types block sponge)")
    )
    problem = tmp_path / "problem.pddl"
    text = random_problem(3, 0, NAMINGS["typed"])
    problem.write_text(text.replace("- block)", "- block s1 - sponge)"))
    with pytest.raises(InputError, match=r"s1 is not a block \(block types: block\)"):
        solve_problem(load_problem(domain, problem), "learned")


RENAMED = ROOT / "models/pddl/variants/blocksworld-renamed.pddl"


def _without_cube(tmp_path: Path, block: str) -> Path:
    """tests/data/renamed_5.pddl with no (cube BLOCK): the renamed variant's static
    precondition of both picks, so BLOCK can never be picked up."""
    text = (DATA / "renamed_5.pddl").read_text()
    assert text.count(f"(cube {block})") == 1
    problem = tmp_path / f"no_cube_{block}.pddl"
    problem.write_text(text.replace(f"(cube {block})", ""))
    return problem


def test_a_goal_that_moves_a_block_no_action_may_pick_is_no_plan_as_the_classical_say(tmp_path):
    # c lacks (cube c) but the goal puts it on d: no plan exists. The learned planner says
    # so as the classical planners do (exit 1, their proof and diagnosis), never a plan
    # that picks c up (the registry's "returned an invalid plan", exit 2).
    problem_file = _without_cube(tmp_path, "c")
    problem = load_problem(RENAMED, problem_file)
    with pytest.raises(NoPlanError) as classical:
        solve_problem(problem, "auto")
    with pytest.raises(NoPlanError) as learned:
        solve_problem(problem, "learned")
    assert str(learned.value) == str(classical.value)
    r = _cli("cake_drake.plan", str(RENAMED), str(problem_file), "--planner", "learned")
    assert r.returncode == 1, r.stderr
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
    assert "no plan exists for problem 'renamed-5'" in r.stderr
    assert "goal (atop c d) is unreachable" in r.stderr


def test_the_network_is_offered_only_the_actions_the_static_preconditions_allow(
    tmp_path, monkeypatch
):
    # e lacks (cube e), lies clear on the floor and the goal leaves it there: a plan
    # exists that never picks e up, and picking it up is never among the choices.
    from cake_drake.symbolic import learned as module

    offered = []
    scores = module.scores

    def spy(weights, graph, actions):
        offered.extend(actions)
        return scores(weights, graph, actions)

    monkeypatch.setattr(module, "scores", spy)
    problem = parse_problem(
        load_domain(RENAMED),
        """(define (problem e-stays) (:domain cube-stacking) (:objects a b c d e)
             (:init (cube a) (cube b) (cube c) (cube d) (on-floor c) (atop b c) (atop a b)
                    (free a) (on-floor d) (free d) (on-floor e) (free e) (gripper-free))
             (:goal (and (atop c d) (atop b c) (atop a b))))""",
    )
    plan = solve_problem(problem, "learned")
    assert validate_plan(problem, plan.actions).ok
    e = sorted(problem.objects).index("e")
    assert offered and not [a for a in offered if a[0] in ("pick-up", "unstack") and a[1] == e]


def test_no_plan_within_its_budget_is_the_no_plan_exit_with_the_reason(tmp_path):
    # A network of zero weights scores every action alike: it takes the first one each
    # time, picking a block up and putting it down again (a loop).
    zero = {k: np.zeros(s, np.float32) for k, s in weight_shapes(8).items()}
    zero["norm_g"][:] = 1.0
    export(zero, 8, {"blocks": [3, 6]}, tmp_path / "zero")
    with pytest.raises(NoPlanError, match="returns to a state already visited"):
        solve_problem(load_problem(BLOCKSWORLD_DOMAIN, PROBLEM_5), f"learned@{tmp_path / 'zero'}")
    r = _cli("cake_drake.plan", "--planner", f"learned@{tmp_path / 'zero'}")
    assert r.returncode == 1 and "(a loop)" in r.stderr and r.stderr.count("\n") == 1


def test_learned_at_a_folder_is_never_taken_for_a_plugin(tmp_path):
    from cake_drake.plugins import is_plugin

    assert not is_plugin("learned@package://cake_drake/planners/blocks")
    assert not is_plugin("learned@C:/planners/blocks")
    assert is_plugin("examples.pid_controller:make")
    problem = load_problem(BLOCKSWORLD_DOMAIN, PROBLEM_5)
    plan = solve_problem(problem, "learned@package://cake_drake/planners/blocks")
    assert plan.length == 10


def _pddl_facts(below, names) -> list[str]:
    facts = []
    for i, j in enumerate(below):
        if j == -1:
            facts.append(f"(on-table {names[i]})")
        elif j == -2:
            facts.append(f"(holding {names[i]})")
        else:
            facts.append(f"(on {names[i]} {names[j]})")
    covered = {j for j in below if j >= 0}
    facts += [f"(clear {names[i]})" for i, j in enumerate(below) if i not in covered and j != -2]
    if -2 not in below:
        facts.append("(arm-empty)")
    return facts


def _goal_distances(sample, tmp_path) -> tuple[dict[frozenset, int], list[str]]:
    """Every state's number of actions to the sample's goal, found by pyperplan's own
    grounding of models/pddl/blocksworld.pddl (nothing of the learned planner's model):
    the whole state space searched from the sample's state, then breadth first from the
    goal states backwards (every edge kept both ways as pyperplan grounds it)."""
    from collections import deque

    from pyperplan.grounding import ground
    from pyperplan.pddl.parser import Parser

    g = sample.graph
    names = [f"b{i}" for i in range(len(g.below))]
    goal = [f"(on {names[i]} {names[j]})" if j >= 0 else f"(on-table {names[i]})"
            for i, j in enumerate(g.goal_below) if j != -3]  # fmt: skip
    goal += [f"(clear {names[i]})" for i, c in enumerate(g.goal_clear) if c]
    goal += [f"(holding {names[i]})" for i, h in enumerate(g.goal_held) if h]
    goal += ["(arm-empty)"] if g.goal_arm_empty else []
    problem = tmp_path / "p.pddl"
    problem.write_text(
        f"(define (problem p) (:domain blocksworld) (:objects {' '.join(names)})\n"
        f"(:init {' '.join(_pddl_facts(g.below, names))})\n(:goal (and {' '.join(goal)})))\n"
    )
    task = ground(Parser(str(ROOT / "models/pddl/blocksworld.pddl"), str(problem)).parse_problem(
        Parser(str(ROOT / "models/pddl/blocksworld.pddl")).parse_domain()))  # fmt: skip
    start, seen, edges = task.initial_state, {task.initial_state}, {}
    queue = deque([start])
    while queue:
        s = queue.popleft()
        edges[s] = [op.apply(s) for op in task.operators if op.applicable(s)]
        for t in edges[s]:
            if t not in seen:
                seen.add(t)
                queue.append(t)
    dist = {s: 0 for s in seen if task.goal_reached(s)}
    queue = deque(dist)
    back = {s: [] for s in seen}
    for s, ts in edges.items():
        for t in ts:
            back[t].append(s)
    while queue:
        t = queue.popleft()
        for s in back[t]:
            if s not in dist:
                dist[s] = dist[t] + 1
                queue.append(s)
    return dist, names


def test_training_labels_are_exact(tmp_path):
    # The labels against an independent count: pyperplan grounds the domain file, every
    # state's distance to the goal is searched there, and an action is labelled optimal
    # exactly when it leads to a state one action closer.
    space = Space(4)
    assert len(space.states) == 125  # 73 arrangements with the arm empty, 52 holding one
    data = samples(PlannerRecipe(min_blocks=3, max_blocks=4, goals=12, states_per_goal=4),
                   log=lambda *_: None)  # fmt: skip
    assert len(data) >= 24
    checked = 0
    for sample in data:
        dist, names = _goal_distances(sample, tmp_path)
        here = dist[frozenset(_pddl_facts(sample.graph.below, names))]
        assert here > 0  # a labelled state is not at its goal
        for action, optimal in zip(sample.actions, sample.optimal, strict=True):
            after = list(sample.graph.below)
            kind, x, y = action
            after[x] = -2 if kind in ("pick-up", "unstack") else (-1 if kind == "put-down" else y)
            closer = dist[frozenset(_pddl_facts(after, names))] == here - 1
            assert bool(optimal) == closer, (sample.graph, action)
            checked += 1
    assert checked > 100


@pytest.mark.slow
def test_a_run_with_the_learned_top_replans_after_a_fault_and_draws_its_cake(tmp_path):
    r = _cli("cake_drake.run", "--planner", "learned", "--no-render",
             "--fault", "knock:d@1", "--out", str(tmp_path))  # fmt: skip
    assert r.returncode == 0, r.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["replans"] >= 1, summary["events"]
    assert summary["layers"]["symbolic"]["kind"] == "learned"
    assert "relational network" in summary["layers"]["symbolic"]["what"]
    assert summary["layers"]["geometric"]["kind"] == "classical"
    assert "symbolic learned (learned, relational network" in r.stderr
    # The picture says it too: the top tier in the learned colour, the others classical,
    # on the simulator's truth.
    from matplotlib.colors import to_rgb
    from matplotlib.image import imread

    from cake_drake.outputs.cake import COLOURS, LAYERS, cake_figure

    image = imread(tmp_path / "cake.png")[:, :, :3]
    fig = cake_figure(summary["layers"])
    ax = fig.axes[0]
    boxes = sorted((p for p in ax.patches if p.get_width() > 5), key=lambda p: -p.get_y())
    for name, box in zip(LAYERS, boxes, strict=True):
        px, py = ax.transData.transform((box.get_x() + box.get_width() - 0.4, box.get_y() + 0.15))
        colour = image[int(image.shape[0] - py), int(px)]
        kind = {"symbolic": "learned", "perception": "truth"}.get(name, "classical")
        assert np.allclose(colour, to_rgb(COLOURS[kind]), atol=0.02), name


# --- the same network from the goal's reward alone -------------------------------------------


def test_the_reward_s_baseline_and_log_probabilities_by_hand():
    import torch

    from cake_drake.learning.training.planner_reward import _log_probs, advantages

    r = np.array([1.0, 0.5, 0.0, 2.0, 2.0])
    problem = np.array([0, 0, 0, 1, 1])
    # each episode against the mean of its problem's others; a problem all alike: zeros
    np.testing.assert_allclose(advantages(r, problem), [0.75, 0.0, -0.75, 0.0, 0.0])
    # two states: three actions (the second chosen) and two (the first chosen)
    score = torch.tensor([1.0, 2.0, 3.0, 0.0, 0.0], requires_grad=True)
    logp, entropy = _log_probs(score, np.array([0, 0, 0, 1, 1]), np.array([0, 1, 0, 1, 0]), 2)
    e = np.exp([1.0, 2.0, 3.0])
    p = e / e.sum()
    np.testing.assert_allclose(logp.detach().numpy(), [np.log(p[1]), np.log(0.5)], rtol=1e-6)
    np.testing.assert_allclose(entropy.detach().numpy(), [-(p * np.log(p)).sum(), np.log(2)],
                               rtol=1e-6)  # fmt: skip


def test_a_few_updates_from_the_reward_alone_learn_small_problems(tmp_path):
    import torch

    from cake_drake.learning.training.planner import _model
    from cake_drake.learning.training.planner_reward import (
        RewardRecipe,
        evaluate,
        train_planner_reward,
    )

    before = evaluate(_model(64, 0), (3,), 64, 7)[3][0]
    info = train_planner_reward(RewardRecipe(steps=40, max_blocks=3, check_sizes=(4,)), tmp_path,
                                log=lambda _: None)  # fmt: skip
    p = _model(64, 0)
    with torch.no_grad(), np.load(tmp_path / "weights.npz") as w:
        for k in w.files:
            p[k].copy_(torch.as_tensor(w[k]))
    after = evaluate(p, (3,), 64, 7)[3][0]
    # greedy play of 64 three-block problems: from loops to planning
    assert before < 0.5 and after >= 0.9, (before, after)
    assert info["labels"].startswith("none: the goal's reward alone")


def test_a_planner_trained_from_the_reward_a_few_steps_plans_problem_5_or_refuses(tmp_path):
    out = tmp_path / "reward"
    r = _cli("cake_drake.train", "--planner", "--reward", "--out", str(out), "--steps", "20",
             "--blocks", "2", "4")  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "trained from the reward alone" in r.stdout and f"learned@{out}" in r.stdout
    cfg = json.loads((out / "planner.json").read_text())
    assert cfg["training"]["blocks"] == [2, 4] and cfg["training"]["steps"] == 20
    r = _cli("cake_drake.plan", "--planner", f"learned@{out}")
    assert r.returncode in (0, 1), r.stderr
    if r.returncode == 0:
        assert "from the reward" in r.stdout
    else:
        assert r.stderr.count("\n") == 1 and "gave up" in r.stderr
    r = _cli("cake_drake.plan", str(DATA / "blocks_paint.pddl"), str(PROBLEM_5),
             "--planner", f"learned@{out}")  # fmt: skip
    assert r.returncode == 2 and "blocks_paint.pddl" in r.stderr and "Traceback" not in r.stderr


@pytest.mark.parametrize(
    ("flags", "words"),
    [
        (["--planner", "--reward", "--blocks", "1", "4"], "--blocks 1 4: the curriculum starts"),
        (["--planner", "--reward", "--blocks", "3", "30"], "at most 20 blocks"),
        (["--planner", "--reward", "--steps", "0"], "--steps 0"),
        (["--reward"], "--reward without --planner"),
    ],
)
def test_a_reward_recipe_that_cannot_train_is_one_line(tmp_path, flags, words):
    r = _cli("cake_drake.train", *flags, "--out", str(tmp_path / "o"))
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and words in r.stderr, r.stderr
    assert not (tmp_path / "o").exists()
