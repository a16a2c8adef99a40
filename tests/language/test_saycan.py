"""Language plans vs PDDL: transcripts, lexicon, methods, verdicts, the note, the saycan CLI."""

from __future__ import annotations

import random
import re
import subprocess
import sys

import pytest

from cake_drake.errors import InputError
from cake_drake.language import (
    AMBIGUOUS,
    DONE,
    END_PHRASES,
    KITCHEN_DEFAULT,
    KITCHEN_DOMAIN,
    KITCHEN_PROMPT,
    MAPS_CLEANLY,
    MAPS_TO_SEVERAL,
    MAPS_VIA_METHOD,
    NO_SCHEMA,
    NOT_REACHED,
    PRECONDITION_FAILS,
    TRANSCRIPTS_DIR,
    VERBS,
    analyse,
    load_transcript,
    method_bindings,
    missing_objects,
    parse_transcript,
    render_markdown,
    render_text,
    side_by_side,
    with_objects,
)
from cake_drake.language.mapping import match_verb
from cake_drake.language.report import comparison_rows, render_note
from cake_drake.language.transcript import normalise
from cake_drake.symbolic import (
    MODELS_DIR,
    GroundAction,
    load_problem,
    parse_problem,
    read_plan,
    validate_plan,
)

PDDL = MODELS_DIR / "pddl"


@pytest.fixture(scope="module")
def kitchen():
    return load_problem(KITCHEN_DOMAIN, KITCHEN_DEFAULT, require_goal=False)


@pytest.fixture(scope="module")
def prompt_kitchen():
    return load_problem(KITCHEN_DOMAIN, KITCHEN_PROMPT, require_goal=False)


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


def test_step_number_without_a_space_is_a_step():
    # SayCan, Table 4: "... 4. put down the jalapeno chips, 5.done"
    t = parse_transcript(
        "Robot: 1. find the jalapeno chips, 2. pick up the jalapeno chips, 3. bring it to "
        "you, 4. put down the jalapeno chips, 5.done"
    )
    assert [s.text for s in t.steps][-2:] == ["put down the jalapeno chips", "done"]
    assert [s.number for s in t.steps] == [1, 2, 3, 4, 5]


@pytest.mark.parametrize(
    "text, expected",
    [
        ("1)find a coke 2 ) pick up the coke 3 .done", ["find a coke", "pick up the coke", "done"]),
        ("Step 1: find a coke Step 2. done", ["find a coke", "done"]),
        ("I would: 1. pick up the 7up, 2. done.", ["pick up the 7up", "done"]),
        ("(1) find a coke (2) done", ["find a coke", "done"]),
        ("1. put down 2.5 cans, 2. done", ["put down 2.5 cans", "done"]),
        ("1．find a coke，2. done", ["find a coke", "done"]),  # full-width punctuation
    ],
)
def test_step_numbers_in_any_spacing(text, expected):
    assert [s.text for s in parse_transcript(text).steps] == expected


def test_typographic_punctuation_reads_as_plain():
    t = parse_transcript(
        "Human: Bring me something that isn’t a fruit\nRobot: 1. tell you I’m done."
    )
    assert t.request == "Bring me something that isn't a fruit"
    assert t.steps[0].text == "tell you i'm done"


def test_transcript_without_labels_and_with_odd_numbering():
    t = parse_transcript("1. find an apple 3. done")
    assert [(s.number, s.text) for s in t.steps] == [(1, "find an apple"), (3, "done")]
    assert "not numbered 1, 2, 3" in t.notes[0]


def test_explanation_is_a_note_and_goal_is_read():
    t = parse_transcript(
        "Human: x\nExplanation: I will bring 2. things\nRobot: 1. done\n"
        "Goal: (at-location apple user)"
    )
    assert t.notes == ("Explanation: I will bring 2. things",)
    assert [s.text for s in t.steps] == ["done"]
    assert t.goal == "(at-location apple user)" and t.goal_line == 4


def test_transcript_without_steps_or_with_bad_goal_lines_is_bad_input(tmp_path):
    with pytest.raises(InputError, match="no numbered robot steps found"):
        parse_transcript("Human: hello\nRobot: I cannot help with that.", "t.txt")
    with pytest.raises(InputError, match=r"t.txt:3: a second Goal: line"):
        parse_transcript("Robot: 1. done\nGoal: (a)\nGoal: (b)", "t.txt")
    with pytest.raises(InputError, match=r"t.txt:2: empty Goal: line"):
        parse_transcript("Robot: 1. done\nGoal:", "t.txt")
    f = tmp_path / "t.txt"
    f.write_bytes(b"\xff\xd8\xff\xe0\x00\x10JFIF")
    with pytest.raises(InputError, match="not a text file"):
        load_transcript(f)


# Step texts a language model writes (none ends in a number, which a reader could not
# tell from the next step's number either).
_STEP_TEXTS = [
    "find a coke",
    "pick up the 7up",
    "go to the far counter",
    "put down the rice chips",
    "bring it to you",
    "open the top drawer",
    "close the top drawer",
    "find the jalapeno chips",
    "go to trash can",
    "pick up the water bottle",
    "put down 2 cans on the table",
    "tell you I'm done",
    "done",
    "let go of the grapefruit soda",
    "find an apple and",
]


def _typographic(text: str, rng: random.Random) -> str:
    text = text.replace("'", rng.choice(["'", "\u2019"]))
    if rng.random() < 0.3:
        text = text[0].upper() + text[1:]
    if rng.random() < 0.1:
        text = text.upper()
    if rng.random() < 0.3:
        text = text.replace(" ", rng.choice(["  ", "\u00a0", " \t"]), 1)
    return text + rng.choice(["", "", ".", ",", ";", "!"])


def test_random_layouts_are_split_as_a_person_would():
    rng = random.Random(18)
    numberings = [
        "{}.",
        "{}. ",
        "{} . ",
        "{})",
        "{}) ",
        "({}) ",
        "Step {}: ",
        "step {}. ",
        "{}:",
        "{}\uff0e",  # full-width full stop
    ]
    separators = [", ", " ", ",", "; ", "\n", " \n", ",\n", "\n\n", " and "]
    prefixes = ["Robot: ", "Robot: I would: ", "Robot:\n", "", "I would ", "Robot: I would "]
    for _ in range(500):
        texts = [rng.choice(_STEP_TEXTS) for _ in range(rng.randrange(1, 12))]
        numbering = rng.choice(numberings)  # one style per transcript, as people write
        body = ""
        for i, text in enumerate(texts, start=1):
            if i > 1:
                body += rng.choice(separators)
            body += numbering.format(i) + rng.choice(["", "", " "]) + _typographic(text, rng)
        source = "Human: Could you help?\n" + rng.choice(prefixes) + body
        t = parse_transcript(source)
        assert [s.number for s in t.steps] == list(range(1, len(texts) + 1)), source
        assert [s.text for s in t.steps] == [normalise(x) for x in texts], source
        assert t.request == "Could you help?"


# ------------------------------------------------------------------ the lexicon and methods


def test_every_skill_phrase_matches_itself():
    for verb in VERBS:
        for phrase in verb.phrases:
            text = phrase.replace("{x}", "the apple").replace("{y}", "the drawer")
            matched = match_verb(text)
            assert matched is not None and matched[0].skill == verb.skill, text


def test_every_method_names_schemas_parameters_and_predicates_of_the_kitchen(kitchen):
    domain = kitchen.domain
    for verb in VERBS:
        assert verb.methods[-1].literal or not verb.methods[-1].pre, verb.skill
        for method in verb.methods:
            for ms in method.steps:
                schema = domain.actions[ms.schema]
                assert {p for p, _ in ms.args} <= {p for p, _ in schema.params}
            for pattern in method.pre:
                assert pattern[0] in domain.predicates, (method.name, pattern)


def test_saycan_end_markers_are_end_phrases():
    assert {"done", "tell you i'm done", "i'm done"} <= set(END_PHRASES)


def test_method_bindings_is_a_conjunctive_query():
    put_down = next(v for v in VERBS if v.skill == "put down").methods[0]
    state = frozenset(
        {
            ("at-location", "robot", "trash-area"),
            ("container-at", "trash-can", "trash-area"),
            ("is-open", "trash-can"),
            ("container-at", "bowl", "bowl-area"),
            ("is-open", "bowl"),
        }
    )
    assert method_bindings(put_down, state, {"x": "coke"}) == [
        {"?c": "trash-can", "?l": "trash-area"}
    ]
    closed = state - {("is-open", "trash-can")}
    assert method_bindings(put_down, closed, {"x": "coke"}) == []
    literal = next(v for v in VERBS if v.skill == "put down").methods[-1]
    assert method_bindings(literal, closed, {"x": "coke"}) == [{}]


# ------------------------------------------------------------------ the default kitchen


def test_default_kitchen_is_saycans(kitchen):
    saycan_objects = (
        "7up, apple, tea, multigrain chips, kettle chips, jalapeno chips, rice chips, coke, "
        "grapefruit soda, pepsi, redbull, energy bar, lime soda, sponge, water bottle"
    ).split(", ")
    for noun in saycan_objects + ["close counter", "far counter", "table", "trash", "bowl"]:
        a = run(f"1. go to the {noun}", kitchen)
        assert a.steps[0].verdict == MAPS_CLEANLY, (noun, a.steps[0].detail)
    assert not kitchen.has_goal


# ------------------------------------------------------------------ each verdict kind


def test_maps_cleanly(kitchen):
    a = run("1. find the lime soda, 2. pick up the lime soda, 3. bring it to you, 4. done", kitchen)
    assert verdicts(a) == [MAPS_CLEANLY] * 3 + [DONE]
    assert [str(x) for x in a.actions] == [
        "(find lime-soda close-counter far-counter)",
        "(pick-up lime-soda far-counter)",
        "(bring-to-user lime-soda far-counter)",
    ]
    assert a.ok and a.executable and not a.problem.has_goal


def test_put_down_at_the_trash_can_is_put_in_through_a_method(kitchen):
    # SayCan throws things away as "go to the trash can, put down the X".
    a = run(
        "Robot: 1. find a redbull, 2. pick up the redbull, 3. go to the trash can, "
        "4. put down the redbull, 5. done.\nGoal: (contains trash-can redbull)",
        kitchen,
    )
    assert verdicts(a) == [MAPS_CLEANLY] * 3 + [MAPS_VIA_METHOD, DONE]
    step = a.steps[3]
    assert step.actions == (GroundAction("put-in", ("redbull", "trash-can", "trash-area")),)
    assert step.method is not None and step.method.name == "put-into-container-here"
    assert "trash-area, where the open trash-can stands" in step.why
    assert a.ok and a.unmet_goals == ()
    # The same words where no container stands are the literal put-down.
    b = run("1. pick up the sponge, 2. put down the sponge", kitchen)
    assert verdicts(b) == [MAPS_CLEANLY, MAPS_CLEANLY]
    assert str(b.actions[-1]) == "(put-down sponge close-counter)"


def test_put_down_at_an_open_drawer_and_pick_up_out_of_it(kitchen):
    a = run(
        "1. open the top drawer 2. find the coke 3. pick up the coke 4. go to the close counter "
        "5. put down the coke 6. pick up the coke 7. done",
        kitchen,
    )
    assert verdicts(a) == [MAPS_CLEANLY] * 4 + [MAPS_VIA_METHOD, MAPS_VIA_METHOD, DONE]
    assert str(a.actions[4]) == "(put-in coke top-drawer close-counter)"
    assert str(a.actions[5]) == "(take-out coke top-drawer close-counter)"
    assert a.steps[5].method.name == "take-out-of-container"


def test_a_method_that_applies_in_two_ways_is_ambiguous(kitchen):
    a = run(
        "1. open the top drawer 2. open the bottom drawer 3. pick up the sponge "
        "4. put down the sponge",
        kitchen,
    )
    assert verdicts(a) == [MAPS_CLEANLY] * 3 + [AMBIGUOUS]
    assert a.steps[3].candidates == ("bottom-drawer", "top-drawer")


def test_maps_to_several_actions_names_its_method(kitchen):
    a = run("1. pick up the sponge 2. throw away the sponge 3. done", kitchen)
    assert verdicts(a) == [MAPS_CLEANLY, MAPS_TO_SEVERAL, DONE]
    several = a.steps[1]
    assert [str(x) for x in several.actions] == [
        "(go-to close-counter trash-area)",
        "(put-in sponge trash-can trash-area)",
    ]
    assert several.method.name == "go-to-trash-then-put-in"
    # Already at the trash can, the other method fires: one action, no go-to.
    b = run("1. pick up the sponge 2. go to the trash 3. throw away the sponge", kitchen)
    assert verdicts(b) == [MAPS_CLEANLY, MAPS_CLEANLY, MAPS_VIA_METHOD]
    assert b.steps[2].method.name == "put-in-trash-here"


def test_precondition_fails_names_the_unmet_fact(kitchen):
    a = run(
        "1. pick up the sponge, 2. open the top drawer, 3. put the sponge in the top drawer, "
        "4. done",
        kitchen,
    )
    assert verdicts(a) == [MAPS_CLEANLY, PRECONDITION_FAILS, NOT_REACHED, DONE]
    failed = a.steps[1]
    assert failed.unmet == (("hand-empty",),)
    assert "the robot's hand is not empty" in failed.detail
    assert a.failed_action == GroundAction("open", ("top-drawer", "close-counter"))
    assert a.actions == (GroundAction("pick-up", ("sponge", "close-counter")),)
    assert not a.ok and not a.executable


def test_precondition_fails_picks_the_informative_binding_and_suggests_a_find(kitchen):
    # The robot is at the close counter; the tea is on the far one.
    a = run("1. pick up the tea", kitchen)
    (r,) = a.steps
    assert r.verdict == PRECONDITION_FAILS
    assert r.actions == (GroundAction("pick-up", ("tea", "far-counter")),)
    assert r.unmet == (("at-location", "robot", "far-counter"),)
    assert "the robot is not at far-counter" in r.detail
    assert "a 'find tea' step would have taken it there" in r.need


def test_an_ambiguous_noun_is_reported_with_its_candidates(kitchen):
    a = run("Human: move it to the close counter\nRobot: 1. go to the counter 2. done", kitchen)
    r = a.steps[0]
    assert r.verdict == AMBIGUOUS and r.candidates == ("close-counter", "far-counter")
    assert "'counter' is ambiguous" in r.detail and "the request names 'close counter'" in r.detail
    b = run("1. find the chips", kitchen)
    assert b.steps[0].verdict == AMBIGUOUS
    assert b.steps[0].candidates == (
        "jalapeno-chips",
        "kettle-chips",
        "multigrain-chips",
        "rice-chips",
    )


def test_nouns_with_packaging_plurals_aliases_and_a_unique_head(kitchen):
    for phrase, obj in [
        ("the coke can", "coke"),
        ("a can of coke", "coke"),
        ("the 7up", "seven-up"),
        ("the apples", "apple"),
        ("a bag of rice chips", "rice-chips"),
        ("the bar", "energy-bar"),
    ]:
        a = run(f"1. find {phrase}", kitchen)
        assert a.actions and a.actions[0].args[0] == obj, phrase


def test_no_schema_for_unknown_verb_lists_the_skills(kitchen):
    a = run("1. find an apple 2. juggle the apple 3. done", kitchen)
    assert verdicts(a) == [MAPS_CLEANLY, NO_SCHEMA, DONE]
    detail = a.steps[1].detail
    assert detail.startswith("verb 'juggle' is not in the lexicon (skills: throw away, clean up")


def test_no_schema_for_unknown_object_lists_the_objects(kitchen):
    a = run("1. find a banana 2. pick up the banana 3. done", kitchen)
    assert verdicts(a) == [NO_SCHEMA, NO_SCHEMA, DONE]
    assert a.steps[0].detail.startswith("'banana' is not an object of problem 'kitchen-saycan'")
    assert "apple, bottom-drawer, bowl, bowl-area, close-counter, coke" in a.steps[0].detail


def test_no_schema_for_a_wrong_kind_of_object(kitchen):
    a = run("1. pick up the table", kitchen)
    assert a.steps[0].verdict == NO_SCHEMA
    assert (
        "'table' has type 'location' but ?i of (pick-up ?i ?l) needs type 'item'"
        in a.steps[0].detail
    )


def test_it_is_the_last_item_and_names_what_it_stood_for(kitchen):
    a = run("1. bring it to you", kitchen)
    assert a.steps[0].detail == "'it' refers to nothing: no earlier step names an item"
    b = run("1. find a banana, 2. bring it to you, 3. done", kitchen)
    assert verdicts(b) == [NO_SCHEMA, NO_SCHEMA, DONE]
    assert b.steps[1].detail.startswith("'it' stands for 'banana' (step 1), which names no object")
    c = run("1. pick up the sponge, 2. go to the table, 3. put it down", kitchen)
    assert str(c.actions[-1]) == "(put-down sponge table)"
    d = run("1. find the chips, 2. bring it to you", kitchen)
    assert "'it' stands for 'chips' (step 1)" in d.steps[1].detail


def test_after_done_and_empty_steps(kitchen):
    a = run("1. done 2. find an apple", kitchen)
    assert verdicts(a) == [DONE, "after done"] and a.actions == () and a.ok
    b = run("1. , 2. done", kitchen)
    assert verdicts(b) == [NO_SCHEMA, DONE] and b.steps[0].detail == "the step is empty"


def test_goal_line_is_added_to_a_problem_without_goal(kitchen, drawer_task):
    a = run("Robot: 1. done\nGoal: (at-location apple user)", kitchen)
    assert a.goal_from_transcript and a.problem.goal == {("at-location", "apple", "user")}
    assert a.unmet_goals == (("at-location", "apple", "user"),) and not a.ok
    assert "(:goal (at-location apple user))" in a.problem.text
    b = run("Robot: 1. done\nGoal: (at-location apple user)", drawer_task)
    assert not b.goal_from_transcript and "is not used" in b.notes[0]
    c = run("Robot: 1. done\nGoal: (at-location banana user)", kitchen)
    assert "Goal: (t.txt:2) names banana" in c.notes[0] and not c.problem.has_goal
    with pytest.raises(InputError, match=r"t.txt:2: Goal: \(at-location apple\): "):
        run("Robot: 1. done\nGoal: (at-location apple)", kitchen)


# ------------------------------------------------------------------ the plan comparison


def test_side_by_side_alignment():
    A = [GroundAction("a"), GroundAction("b"), GroundAction("c")]
    B = [GroundAction("a"), GroundAction("x"), GroundAction("c"), GroundAction("d")]
    assert side_by_side(tuple(A), tuple(B)) == [
        ("=", "(a)", "(a)"),
        ("~", "(b)", "(x)"),
        ("=", "(c)", "(c)"),
        (">", "", "(d)"),
    ]


def test_side_by_side_marks_the_failed_action_and_does_not_match_it():
    applied = (GroundAction("a"), GroundAction("b"))
    planner = (GroundAction("a"), GroundAction("b"), GroundAction("f"), GroundAction("g"))
    rows = side_by_side(applied, planner, failed=GroundAction("f"))
    assert rows == [
        ("=", "(a)", "(a)"),
        ("=", "(b)", "(b)"),
        ("x", "(f)", ""),
        (">", "", "(f)"),
        (">", "", "(g)"),
    ]


def test_report_counts_applied_actions_only_and_ends_with_the_note(drawer_task):
    a = run(
        "Robot: 1. find the rice chips, 2. pick up the rice chips, 3. go to the top drawer, "
        "4. put the rice chips in the top drawer, 5. close the top drawer, 6. done",
        drawer_task,
        planner="gbfs-ff",
    )
    assert a.failed_action == GroundAction("put-in", ("rice-chips", "top-drawer", "close-counter"))
    assert len(a.actions) == 3
    rows = comparison_rows(a)
    assert ("x", str(a.failed_action), "") in rows
    assert all(mark != "=" or left != str(a.failed_action) for mark, left, _ in rows)
    text = render_text(a)
    assert "3 actions (+1 failed)" in text
    md = render_markdown(a)
    assert "| x | `(put-in rice-chips top-drawer close-counter)` |  |" in md
    note = md[md.index("## Note") :]
    assert md.rstrip().endswith(note.rstrip())
    assert "**Did not map (1):**" in note
    assert "a precondition the language model assumed (step 4): top-drawer is open" in note
    assert "`(open top-drawer close-counter)`" in note  # what the planner did about it


def test_goal_check_and_planner_diff(drawer_task):
    a = run(
        "1. find the rice chips 2. pick up the rice chips 3. go to the top drawer "
        "4. put down the rice chips 5. open the top drawer 6. pick up the rice chips "
        "7. put the rice chips in the top drawer 8. done",
        drawer_task,
        planner="astar-lmcut",
    )
    assert a.executable and a.unmet_goals == (("is-closed", "top-drawer"),) and not a.ok
    assert a.planner_plan is not None and a.planner_plan.length == 6
    assert validate_plan(drawer_task, a.planner_plan.actions).ok
    text = render_text(a)
    assert "GOAL NOT REACHED: all 7 actions apply, unmet goals (is-closed top-drawer)" in text
    assert "6 actions (optimal)" in text
    assert "| = | `(pick-up rice-chips table)` | `(pick-up rice-chips table)` |" in (
        render_markdown(a)
    )
    assert "top-drawer should be closed" in render_markdown(a)


def test_garbage_never_raises_anything_but_input_errors(kitchen, drawer_task):
    rng = random.Random(1)
    words = "find pick up put down in the a it apple chips drawer you bring to open close".split()
    words += "throw away done 1. 2. 3. 4) 5.done Robot: Human: Goal: , . \n spill clean".split(" ")
    words += "coke can é ( ) ; counter trash bowl ’ tell I’m step".split(" ")
    for i in range(400):
        if i % 2:
            text = "".join(chr(rng.randrange(1, 0x2FFF)) for _ in range(rng.randrange(120)))
        else:
            text = " ".join(rng.choice(words) for _ in range(rng.randrange(40)))
        try:
            t = parse_transcript(text)
            a = analyse(t, kitchen if i % 4 else drawer_task, planner=None)
        except InputError:
            continue
        render_text(a)
        render_markdown(a)


# ------------------------------------------------------------------ the shipped transcripts

C, V, S = MAPS_CLEANLY, MAPS_VIA_METHOD, MAPS_TO_SEVERAL
P, A, N, X = PRECONDITION_FAILS, AMBIGUOUS, NOT_REACHED, NO_SCHEMA
ADDED = "+objects"  # SayCan's kitchen with the transcript's missing objects added

#: SayCan's own step lists: (problem or None for the default kitchen, ok, verdicts).
CITED = {
    "saycan_spill_sponge": (None, True, [C, C, C, DONE]),
    "saycan_lime_soda": (None, True, [C] * 4 + [DONE]),
    "saycan_jalapeno_chips": (None, True, [C] * 4 + [DONE]),
    "saycan_snacks": (None, True, [C] * 8 + [DONE]),
    "saycan_grapefruit_counter": (None, False, [C, C, A, N, DONE]),
    "saycan_rice_chips_bowl": (None, False, [C, C, C, V, P, N, N, DONE]),
    "saycan_kettle_chips_here": (None, False, [P, DONE]),
    "saycan_mountain_dew": ("kitchen_prompt", True, [C, C, C, V, C, C, C, C, DONE]),
    "saycan_coffee_cup": ("kitchen_prompt", True, [C, C, C, V, DONE]),
    "saycan_grapes_cheese": ("kitchen_prompt", False, [C, C, C, V, P, N, N, DONE]),
    # The rest of the planning prompt: SayCan's kitchen, with --add-objects where the
    # example names things the kitchen lacks (ADDED).
    "saycan_snickers": (ADDED, False, [P, DONE]),
    "saycan_trailmix_here": (ADDED, False, [P, DONE]),
    "saycan_water_oatmeal_microwave": (ADDED, True, [C] * 8 + [DONE]),
    "saycan_grapefruit_bowl": (ADDED, True, [C, C, C, V, DONE]),
    "saycan_sponge_sink": (None, True, [C, C, C, V, DONE]),
    "saycan_water_bottle_counter": (None, False, [C, C, A, N, DONE]),
    "saycan_twix_dried_fruit": (ADDED, True, [C] * 8 + [DONE]),
    "saycan_orange": (ADDED, True, [C] * 4 + [DONE]),
    "saycan_coke_can": (None, True, [C] * 4 + [DONE]),
    "saycan_banana_let_go": (ADDED, False, [P, DONE]),
    "saycan_pick_up_peanuts": (ADDED, False, [P, DONE]),
    "saycan_bring_peanuts": (ADDED, False, [P, N, N, DONE]),
}

#: Our own teaching cases.
OWN = {
    "bring_apple": ("kitchen_snack", True, [C] * 4 + [DONE]),
    "clean_spill": ("kitchen_spill", True, [C, C, S, C, C, S, DONE]),
    "chips_in_drawer": ("kitchen_drawer", False, [C, C, C, P, N, DONE]),
    "chips_in_drawer_fixed": ("kitchen_drawer", True, [C] * 8 + [DONE]),
    "drawer_saycan_style": ("kitchen_drawer", True, [C] * 5 + [V, C, DONE]),
    "warm_snack": (None, False, [C, C, X, X, DONE]),
}
SHIPPED = CITED | OWN


def test_every_shipped_transcript_is_covered_and_the_cited_ones_cite():
    assert {p.stem for p in TRANSCRIPTS_DIR.glob("*.txt")} == set(SHIPPED)
    for name in CITED:
        header = (TRANSCRIPTS_DIR / f"{name}.txt").read_text(encoding="utf-8")
        assert "arXiv:2204.01691" in header and "verbatim" in header, name
        assert "Goal:" in header or "No Goal: line" in header, name
    for name in OWN:
        assert "not taken from the paper" in (TRANSCRIPTS_DIR / f"{name}.txt").read_text()


def _problem(problem_name, kitchen, transcript=None):
    if problem_name is None:
        return kitchen
    if problem_name == ADDED:
        return with_objects(kitchen, missing_objects(transcript, kitchen))
    return load_problem(KITCHEN_DOMAIN, PDDL / f"{problem_name}.pddl", require_goal=False)


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_transcripts_give_the_documented_verdicts(name, kitchen):
    problem_name, ok, expected = SHIPPED[name]
    t = load_transcript(TRANSCRIPTS_DIR / f"{name}.txt")
    a = analyse(t, _problem(problem_name, kitchen, t), planner=None)
    assert verdicts(a) == expected
    assert a.ok == ok
    if name in CITED and t.goal is not None:
        assert a.goal_from_transcript


def test_cited_discard_plans_reach_the_trash_and_the_failures_say_why(kitchen, prompt_kitchen):
    dew = analyse(
        load_transcript(TRANSCRIPTS_DIR / "saycan_mountain_dew.txt"), prompt_kitchen, None
    )
    assert ("contains", "trash-can", "sprite") in dew.final_state and dew.ok
    # In SayCan's own kitchen the prompt's example stops at its first object.
    plain = analyse(load_transcript(TRANSCRIPTS_DIR / "saycan_mountain_dew.txt"), kitchen, None)
    assert plain.steps[0].verdict == NO_SCHEMA and "'sprite can'" in plain.steps[0].detail
    assert "names mountain-dew, sprite, which problem 'kitchen-saycan'" in plain.notes[0]
    assert not plain.problem.has_goal
    tea = analyse(load_transcript(TRANSCRIPTS_DIR / "saycan_rice_chips_bowl.txt"), kitchen, None)
    assert tea.steps[4].unmet == (("at-location", "robot", "far-counter"),)
    assert ("contains", "bowl", "rice-chips") in tea.final_state
    counter = analyse(
        load_transcript(TRANSCRIPTS_DIR / "saycan_grapefruit_counter.txt"), kitchen, None
    )
    assert counter.steps[2].candidates == ("close-counter", "far-counter")
    assert "the request names 'close counter'" in counter.steps[2].detail


def saycan(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cake_drake.saycan", *args],
        capture_output=True,
        text=True,
        timeout=300,
    )


@pytest.mark.parametrize("name", ["saycan_lime_soda", "saycan_rice_chips_bowl", "warm_snack"])
def test_cli_exit_codes_and_outputs(name, tmp_path):
    problem_name, ok, _ = SHIPPED[name]
    args = [str(TRANSCRIPTS_DIR / f"{name}.txt"), "--out", str(tmp_path), "--planner", "gbfs-ff"]
    if problem_name:
        args += ["--problem", str(PDDL / f"{problem_name}.pddl")]
    r = saycan(*args)
    assert r.returncode == (0 if ok else 1), r.stderr
    assert r.stderr == ""
    written = {p.name for p in tmp_path.iterdir() if not p.name.startswith(".")}
    assert written == {"plan.txt", "problem.pddl", "report.md"}
    report = (tmp_path / "report.md").read_text()
    assert report.startswith(f"# Language plan vs PDDL: {name}.txt")
    assert "## Note" in report and "**What would have been needed:**" in report
    problem = load_problem(KITCHEN_DOMAIN, tmp_path / "problem.pddl", require_goal=False)
    result = validate_plan(problem, read_plan(tmp_path / "plan.txt"))
    assert result.ok == ok or not problem.has_goal


def test_cli_default_kitchen_without_goal_checks_executability_only(tmp_path):
    r = saycan(str(TRANSCRIPTS_DIR / "saycan_spill_sponge.txt"), "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    assert "EXECUTABLE: all 3 actions apply in 'kitchen-saycan'" in r.stdout
    assert "planner: not run (the problem has no goal)" in r.stdout


@pytest.mark.parametrize(
    "content, expected",
    [
        (b"", "is empty"),
        (b"\x00\x9c\x01binary", "not a text file"),
        (b"\xc3\x28 not utf-8", "not a UTF-8 text file"),
        (b"just some words, no steps", "no numbered robot steps found"),
        (b"Robot: 1. done\nGoal: (at-location apple)", "t.txt:2: Goal:"),
        (b"Robot: 1. done\nGoal: (at-location apple", "t.txt:2: Goal:"),
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


def test_add_objects_declares_what_the_transcript_names_and_the_kitchen_lacks(tmp_path):
    """SayCan's own kitchen has no banana: without --add-objects its steps have no schema;
    with it the banana is declared (an item: the skill 'find' takes one) at a place of its
    own, and "find a banana" goes there: the plan runs, nothing is blamed on the model."""
    t = tmp_path / "banana.txt"
    t.write_text(
        "Human: Bring me a banana\nRobot: 1. find a banana, 2. pick up the banana, "
        "3. bring it to you, 4. done.\n"
    )
    plain = saycan(str(t), "--out", str(tmp_path / "plain"))
    assert plain.returncode == 1 and "added objects" not in plain.stderr
    assert re.search(r"1\s+find a banana\s+no schema", plain.stdout), plain.stdout
    added = saycan(str(t), "--out", str(tmp_path / "added"), "--add-objects")
    assert added.returncode == 0, added.stdout + added.stderr
    assert "added objects: banana (item)" in added.stderr
    assert re.search(
        r"1\s+find a banana\s+maps cleanly\s+\(find banana close-counter banana-spot\)",
        added.stdout,
    ), added.stdout
    assert "assumed" not in added.stdout
    problem = (tmp_path / "added" / "problem.pddl").read_text()
    assert "banana - item" in problem and "banana-spot - location" in problem
    # The banana stands only at its own spot: no place of the kitchen was chosen for it.
    assert re.findall(r"\(at-location banana [^)]*\)", problem) == [
        "(at-location banana banana-spot)"
    ]


def _with_added_objects(name, kitchen):
    t = load_transcript(TRANSCRIPTS_DIR / f"{name}.txt")
    return analyse(t, with_objects(kitchen, missing_objects(t, kitchen)), planner=None)


def test_an_added_object_is_where_the_first_find_seeks_it_and_the_note_blames_no_one(kitchen):
    """The prompt's throw-away example in SayCan's own kitchen: "find a sprite can" must not
    stop at a place we chose for the can ("sprite-can is at bowl-area"), and the note must
    not call that place a precondition the language model assumed."""
    dew = _with_added_objects("saycan_mountain_dew", kitchen)
    assert dew.steps[0].verdict == MAPS_CLEANLY, dew.steps[0].detail
    assert str(dew.steps[0].actions[0]) == "(find sprite-can close-counter sprite-can-spot)"
    assert dew.executable and verdicts(dew) == [C, C, C, V, C, C, C, C, DONE]
    assert ("contains", "trash-can", "sprite-can") in dew.final_state
    assert ("at-location", "mountain-dew-can", "user") in dew.final_state
    note = "\n".join(render_note(dew))
    assert "assumed" not in note and "bowl-area" not in render_text(dew)


def test_what_the_model_did_assume_about_an_added_object_is_still_named(kitchen):
    """Leaving the place open does not hide the model's real omissions: "pick up the
    peanuts" with no find assumes them within reach, and "pick up the cheese" after the
    grapes assumes the robot already stands where the cheese is (the rice-chips-and-tea
    shape of the chain-of-thought prompt)."""
    peanuts = _with_added_objects("saycan_pick_up_peanuts", kitchen)
    assert peanuts.steps[0].unmet == (("at-location", "robot", "peanut-spot"),)
    note = "\n".join(render_note(peanuts))
    assert (
        "a precondition the language model assumed (step 1): the robot is at peanut-spot "
        "(a 'find peanut' step would have taken it there)" in note
    )
    cheese = _with_added_objects("saycan_grapes_cheese", kitchen)
    assert verdicts(cheese) == [C, C, C, V, P, N, N, DONE]
    assert cheese.steps[4].unmet == (("at-location", "robot", "cheese-spot"),)
    trailmix = _with_added_objects("saycan_trailmix_here", kitchen)
    assert trailmix.steps[0].unmet == (("in-hand", "trailmix"),)


def test_a_thing_the_problem_places_nowhere_is_the_problems_gap_not_the_models(kitchen):
    """A problem of the user's that declares a banana and says nothing of where it is: the
    place the failing find tries is only a binding, and the note says the problem lacks a
    fact instead of naming that place as the language model's assumption."""
    text = kitchen.text.replace("water-bottle - item", "water-bottle banana - item")
    bare = parse_problem(kitchen.domain, text, "bare.pddl", require_goal=False)
    a = run("1. find a banana, 2. pick up the banana, 3. done", bare)
    assert verdicts(a) == [P, N, DONE] and a.steps[0].unplaced == ("banana",)
    note = "\n".join(render_note(a))
    assert "a fact the problem lacks (step 1): a place for banana" in note
    assert "assumed" not in note
    # A thing the problem does place keeps the model's assumption (the chips in hand).
    here = analyse(load_transcript(TRANSCRIPTS_DIR / "saycan_kettle_chips_here.txt"), kitchen, None)
    assert here.steps[0].unplaced == ()
    assert "a precondition the language model assumed (step 1)" in "\n".join(render_note(here))


#: The sentence of docs/saycan.md that states the measurement below.
SURVEY = re.compile(
    r"\*\*(\d+) of the (\d+)\*\* SayCan transcripts map fully with `--add-objects` "
    r"\((\d+) before"
)


def test_the_add_objects_count_in_the_docs_is_the_measured_one(kitchen):
    """Every SayCan transcript that ships, in SayCan's own kitchen with --add-objects: how
    many map fully (every step maps and applies), as docs/saycan.md states."""
    paths = sorted(TRANSCRIPTS_DIR.glob("saycan_*.txt"))
    full = [p.stem for p in paths if _with_added_objects(p.stem, kitchen).executable]
    found = SURVEY.search((MODELS_DIR.parent / "docs" / "saycan.md").read_text())
    assert found, "docs/saycan.md states no add-objects count"
    assert (int(found[1]), int(found[2])) == (len(full), len(paths)), full
    assert int(found[3]) < len(full)
