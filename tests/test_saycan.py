"""Language plans vs PDDL: transcripts, lexicon, verdicts, the saycan CLI."""

from __future__ import annotations

import random
import subprocess
import sys

import pytest

from cake_drake.errors import InputError
from cake_drake.language import (
    KITCHEN_DEFAULT,
    KITCHEN_DOMAIN,
    MAPS_CLEANLY,
    MAPS_TO_SEVERAL,
    NO_SCHEMA,
    NOT_REACHED,
    PRECONDITION_FAILS,
    TRANSCRIPTS_DIR,
    VERBS,
    analyse,
    load_transcript,
    parse_transcript,
    render_markdown,
    render_text,
    side_by_side,
)
from cake_drake.language.mapping import DONE, match_verb
from cake_drake.symbolic import MODELS_DIR, GroundAction, load_problem, read_plan, validate_plan

PDDL = MODELS_DIR / "pddl"


@pytest.fixture(scope="module")
def kitchen():
    return load_problem(KITCHEN_DOMAIN, KITCHEN_DEFAULT, require_goal=False)


@pytest.fixture(scope="module")
def drawer_task():
    return load_problem(KITCHEN_DOMAIN, PDDL / "kitchen_drawer.pddl")


def run(text: str, problem, planner=None):
    return analyse(parse_transcript(text, "t.txt"), problem, planner)


def verdicts(analysis) -> list[str]:
    return [r.verdict for r in analysis.steps]


# ------------------------------------------------------------------ transcripts


def test_one_line_and_one_step_per_line_layouts_parse_the_same():
    one = parse_transcript(
        "Human: bring me a coke\n"
        "Robot: I would 1. find a coke, 2. pick up the coke, 3. bring it to you, 4. done."
    )
    many = parse_transcript(
        "# a comment\nHuman: bring me a coke\nRobot:\n1. find a coke\n2. Pick up the coke\n"
        "3. bring it to you\n4. done\n"
    )
    assert one.request == many.request == "bring me a coke"
    assert [s.text for s in one.steps] == [s.text for s in many.steps]
    assert [s.text for s in one.steps] == [
        "find a coke",
        "pick up the coke",
        "bring it to you",
        "done",
    ]
    assert [s.line for s in many.steps] == [4, 5, 6, 7]
    assert one.notes == many.notes == ()


def test_transcript_without_labels_and_with_odd_numbering():
    t = parse_transcript("1. find an apple 3. done")
    assert [(s.number, s.text) for s in t.steps] == [(1, "find an apple"), (3, "done")]
    assert "not numbered 1, 2, 3" in t.notes[0]


def test_transcript_without_steps_is_bad_input(tmp_path):
    with pytest.raises(InputError, match="no numbered robot steps found"):
        parse_transcript("Human: hello\nRobot: I cannot help with that.", "t.txt")
    f = tmp_path / "t.txt"
    f.write_bytes(b"\xff\xd8\xff\xe0\x00\x10JFIF")
    with pytest.raises(InputError, match="not a text file"):
        load_transcript(f)


# ------------------------------------------------------------------ the lexicon


def test_every_skill_phrase_matches_itself():
    for verb in VERBS:
        for phrase in verb.phrases:
            text = phrase.replace("{x}", "the apple").replace("{y}", "the drawer")
            matched = match_verb(text)
            assert matched is not None and matched[0].skill == verb.skill, text


def test_every_schema_named_by_the_lexicon_exists_in_the_kitchen(kitchen):
    for verb in VERBS:
        for method in verb.methods:
            for ms in method:
                schema = kitchen.domain.actions[ms.schema]
                assert {p for p, _ in ms.args} <= {p for p, _ in schema.params}


# ------------------------------------------------------------------ each verdict kind


def test_maps_cleanly(kitchen):
    a = run("1. find the sprite, 2. pick up the sprite, 3. bring it to you, 4. done", kitchen)
    assert verdicts(a) == [MAPS_CLEANLY] * 3 + [DONE]
    assert [str(x) for x in a.actions] == [
        "(find sprite-can near-counter far-counter)",
        "(pick-up sprite-can far-counter)",
        "(bring-to-user sprite-can far-counter)",
    ]
    assert a.ok and a.executable and not a.problem.has_goal


def test_maps_to_several_actions(kitchen):
    a = run("1. pick up the sponge 2. throw away the sponge 3. done", kitchen)
    assert verdicts(a) == [MAPS_CLEANLY, MAPS_TO_SEVERAL, DONE]
    several = a.steps[1]
    assert [str(x) for x in several.actions] == [
        "(go-to near-counter trash-area)",
        "(put-in sponge trash-can trash-area)",
    ]
    assert "implicit decomposition" in several.detail
    assert ("contains", "trash-can", "sponge") in a.final_state


def test_precondition_fails_names_the_unmet_fact(kitchen):
    a = run(
        "1. pick up the chips, 2. open the drawer, 3. put the chips in the drawer, 4. done", kitchen
    )
    assert verdicts(a) == [MAPS_CLEANLY, PRECONDITION_FAILS, NOT_REACHED, DONE]
    failed = a.steps[1]
    assert failed.unmet == (("hand-empty",),)
    assert "the robot's hand is not empty" in failed.detail
    assert [str(x) for x in a.actions][-1] == "(open top-drawer near-counter)"
    assert not a.ok and not a.executable


def test_precondition_fails_picks_the_informative_binding(kitchen):
    # The robot is at the near counter; the apple is on the far one.
    a = run("1. pick up the apple", kitchen)
    (r,) = a.steps
    assert r.verdict == PRECONDITION_FAILS
    assert r.actions == (GroundAction("pick-up", ("apple", "far-counter")),)
    assert r.unmet == (("at-location", "robot", "far-counter"),)
    assert "the robot is not at far-counter" in r.detail


def test_pick_up_out_of_an_open_drawer_uses_the_second_method(kitchen):
    a = run("1. open the drawer 2. pick up the granola bar 3. done", kitchen)
    assert verdicts(a) == [MAPS_CLEANLY, MAPS_CLEANLY, DONE]
    assert str(a.actions[1]) == "(take-out granola-bar top-drawer near-counter)"


def test_no_schema_for_unknown_verb_lists_the_skills(kitchen):
    a = run("1. find an apple 2. juggle the apple 3. done", kitchen)
    assert verdicts(a) == [MAPS_CLEANLY, NO_SCHEMA, DONE]
    detail = a.steps[1].detail
    assert detail.startswith("verb 'juggle' is not in the lexicon (skills: throw away, clean up")


def test_no_schema_for_unknown_object_lists_the_objects(kitchen):
    a = run("1. find a banana 2. pick up the banana 3. done", kitchen)
    assert verdicts(a) == [NO_SCHEMA, NO_SCHEMA, DONE]
    assert a.steps[0].detail.startswith("'banana' is not an object of problem 'kitchen-default'")
    assert "apple, bottom-drawer, chips, coke-can" in a.steps[0].detail


def test_no_schema_for_a_wrong_kind_of_object(kitchen):
    a = run("1. pick up the table", kitchen)
    assert a.steps[0].verdict == NO_SCHEMA
    assert (
        "'table' has type 'location' but ?i of (pick-up ?i ?l) needs type 'item'"
        in a.steps[0].detail
    )


def test_pronoun_without_antecedent(kitchen):
    a = run("1. bring it to you", kitchen)
    assert a.steps[0].detail == "'it' refers to nothing mentioned before"


def test_after_done_and_empty_steps(kitchen):
    a = run("1. done 2. find an apple", kitchen)
    assert verdicts(a) == [DONE, "after done"] and a.actions == () and a.ok
    b = run("1. , 2. done", kitchen)
    assert verdicts(b) == [NO_SCHEMA, DONE] and b.steps[0].detail == "the step is empty"


def test_goal_check_and_planner_diff(drawer_task):
    a = run(
        "1. find the chips 2. pick up the chips 3. go to the drawer 4. put down the chips "
        "5. open the drawer 6. pick up the chips 7. put the chips in the drawer 8. done",
        drawer_task,
        planner="astar-lmcut",
    )
    assert a.executable and a.unmet_goals == (("is-closed", "top-drawer"),) and not a.ok
    assert a.planner_plan is not None and a.planner_plan.length == 6
    assert validate_plan(drawer_task, a.planner_plan.actions).ok
    text = render_text(a)
    assert "GOAL NOT REACHED: all 7 actions apply, unmet goals (is-closed top-drawer)" in text
    assert "planner (astar-lmcut)" in text and "6 actions (optimal)" in text
    assert "| = | `(find chips near-counter table)` | `(find chips near-counter table)` |" in (
        render_markdown(a)
    )


def test_side_by_side_alignment():
    A = [GroundAction("a"), GroundAction("b"), GroundAction("c")]
    B = [GroundAction("a"), GroundAction("x"), GroundAction("c"), GroundAction("d")]
    assert side_by_side(tuple(A), tuple(B)) == [
        ("=", "(a)", "(a)"),
        ("~", "(b)", "(x)"),
        ("=", "(c)", "(c)"),
        (">", "", "(d)"),
    ]


def test_garbage_never_raises_anything_but_input_errors(kitchen, drawer_task):
    rng = random.Random(1)
    words = "find pick up put down in the a it apple chips drawer you bring to open close".split()
    words += "throw away done 1. 2. 3. Robot: Human: , . \n spill clean coke can é ( ) ;".split(" ")
    for i in range(400):
        if i % 2:
            text = "".join(chr(rng.randrange(1, 0x2FFF)) for _ in range(rng.randrange(120)))
        else:
            text = " ".join(rng.choice(words) for _ in range(rng.randrange(40)))
        try:
            t = parse_transcript(text)
        except InputError:
            continue
        a = analyse(t, kitchen if i % 4 else drawer_task, planner=None)
        render_text(a)
        render_markdown(a)


# ------------------------------------------------------------------ the shipped transcripts

SHIPPED = {
    # transcript: (problem or None for the default kitchen, exit code, verdicts of the steps)
    "bring_apple": ("kitchen_snack", 0, [MAPS_CLEANLY] * 4 + [DONE]),
    "clean_spill": (
        "kitchen_spill",
        0,
        [MAPS_CLEANLY, MAPS_CLEANLY, MAPS_TO_SEVERAL, MAPS_CLEANLY, MAPS_CLEANLY]
        + [MAPS_TO_SEVERAL, DONE],
    ),
    "chips_in_drawer": (
        "kitchen_drawer",
        1,
        [MAPS_CLEANLY] * 3 + [PRECONDITION_FAILS, NOT_REACHED, DONE],
    ),
    "chips_in_drawer_fixed": ("kitchen_drawer", 0, [MAPS_CLEANLY] * 8 + [DONE]),
    "warm_snack": (None, 1, [MAPS_CLEANLY, MAPS_CLEANLY, NO_SCHEMA, NO_SCHEMA, DONE]),
}


def test_every_shipped_transcript_is_covered():
    assert {p.stem for p in TRANSCRIPTS_DIR.glob("*.txt")} == set(SHIPPED)


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_transcripts_give_the_documented_verdicts(name, kitchen):
    problem_name, _, expected = SHIPPED[name]
    problem = (
        load_problem(KITCHEN_DOMAIN, PDDL / f"{problem_name}.pddl") if problem_name else kitchen
    )
    a = analyse(load_transcript(TRANSCRIPTS_DIR / f"{name}.txt"), problem, planner=None)
    assert verdicts(a) == expected


def saycan(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cake_drake.saycan", *args],
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.mark.parametrize("name", ["bring_apple", "chips_in_drawer", "warm_snack"])
def test_cli_exit_codes_and_outputs(name, tmp_path):
    problem_name, code, _ = SHIPPED[name]
    args = [str(TRANSCRIPTS_DIR / f"{name}.txt"), "--out", str(tmp_path)]
    if problem_name:
        args += ["--problem", str(PDDL / f"{problem_name}.pddl")]
    r = saycan(*args)
    assert r.returncode == code, r.stderr
    assert r.stderr == ""
    assert {p.name for p in tmp_path.iterdir()} == {"plan.txt", "problem.pddl", "report.md"}
    report = (tmp_path / "report.md").read_text()
    assert report.startswith(f"# Language plan vs PDDL: {name}.txt")
    problem = load_problem(KITCHEN_DOMAIN, tmp_path / "problem.pddl", require_goal=False)
    result = validate_plan(problem, read_plan(tmp_path / "plan.txt"))
    assert result.ok == (code == 0) or problem_name is None


def test_cli_default_kitchen_checks_executability_only(tmp_path):
    r = saycan(str(TRANSCRIPTS_DIR / "bring_apple.txt"), "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    assert "EXECUTABLE: all 4 actions apply in 'kitchen-default'" in r.stdout
    assert "planner: not run (the problem has no goal)" in r.stdout


@pytest.mark.parametrize(
    "content, expected",
    [
        (b"", "is empty"),
        (b"\x00\x9c\x01binary", "not a text file"),
        (b"\xc3\x28 not utf-8", "not a UTF-8 text file"),
        (b"just some words, no steps", "no numbered robot steps found"),
    ],
)
def test_cli_unreadable_transcripts_exit_2(tmp_path, content, expected):
    f = tmp_path / "t.txt"
    f.write_bytes(content)
    r = saycan(str(f), "--out", str(tmp_path / "out"))
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.count("\n") == 1 and expected in r.stderr


def test_cli_garbage_steps_exit_1_without_traceback(tmp_path):
    f = tmp_path / "t.txt"
    f.write_text("Robot: 1. %$#@! 2. ))(( 3. pick up pick up 4. put in in 5. done")
    r = saycan(str(f), "--out", str(tmp_path / "out"))
    assert r.returncode == 1 and r.stderr == ""
    assert "4 skill steps -- no schema: 4" in r.stdout
    assert "no skill phrase fits 'put in in' (phrases with 'put': put {x} in {y}," in r.stdout


@pytest.mark.parametrize(
    "args, expected",
    [
        (["/no/such.txt"], "no such transcript"),
        ([str(TRANSCRIPTS_DIR / "bring_apple.txt"), "--problem", "/no/p.pddl"], "no such PDDL"),
        ([str(TRANSCRIPTS_DIR / "bring_apple.txt"), "--planner", "x"], "unknown planner 'x'"),
        ([], "the following arguments are required: TRANSCRIPT"),
    ],
)
def test_cli_bad_inputs_exit_2(args, expected):
    r = saycan(*args)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.count("\n") == 1 and expected in r.stderr
