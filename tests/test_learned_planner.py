"""The learned planner: a network in the planner registry, for any number of blocks."""

from __future__ import annotations

import json
import random
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cake_drake.errors import InputError, NoPlanError
from cake_drake.learning.planner import PlannerRecipe, Space, export, samples
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

ROOT = Path(__file__).resolve().parent.parent
DATA = Path(__file__).resolve().parent / "data"


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
        ("missing", "no such learned planner folder"),
        ("empty", "planner.json is missing"),
        ("truncated", "weights.npz: not a learned planner checkpoint: unreadable"),
        ("not json", "planner.json: not a learned planner checkpoint: unreadable JSON (line 1)"),
        ("not a mapping", "holds a list, not a mapping"),
        ("other kind", "field 'kind' is 'a policy'"),
        ("other width", "array enc_w has shape (10, 64), but width 32"),
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


def test_training_labels_are_exact(tmp_path):
    # Every optimal action leads one step closer, and the goal state is at distance 0.
    space = Space(4)
    assert len(space.states) == 125  # 73 arrangements with the arm empty, 52 holding one
    data = samples(PlannerRecipe(goals=8, states_per_goal=4), log=lambda *_: None)
    assert data and all(s.optimal.any() for s in data)


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
    assert (tmp_path / "cake.png").stat().st_size > 10_000
