"""Check a Blocksworld domain written from memory against the textbook's four operators.

:func:`check_domain` reads the domain by structure (the vocabulary of
:mod:`cake_drake.symbolic.roles`: whatever the predicates are called), then,
for every action schema, compares its parameters, preconditions, add and
delete lists with what that action means in Blocksworld (pick from the table,
pick from a block, place on the table, place on a block), and names each
difference with its consequence: "stack does not delete (clear ?y): a block
could then carry two blocks".

Where it can, it also finds the shortest **witness**: a breadth-first search
runs the domain and the textbook Blocksworld side by side from three blocks on
the table, and stops at the first step where they disagree - an action the
domain allows that Blocksworld forbids (the plan that exploits the bug), an
action Blocksworld allows that the domain forbids, or a state the domain
describes wrongly.

Exit codes of ``python -m cake_drake.plan --check-domain DOMAIN``: 0 the domain
means Blocksworld, 1 differences found, 2 the file cannot be read as PDDL.
"""

from __future__ import annotations

import itertools
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field

from cake_drake.symbolic.pddl import (
    ActionSchema,
    Domain,
    Fact,
    GroundAction,
    fact_str,
)
from cake_drake.symbolic.roles import (
    CANONICAL,
    PICK,
    PLACE,
    Vocabulary,
    _NotBlocksworld,
    _read_vocabulary,
    canonical_action,
)

#: Blocks the witness search uses (three suffice for every classic mistake).
WITNESS_BLOCKS = ("a", "b", "c")
#: The witness search's depth limit (actions).
WITNESS_DEPTH = 8

# (kind, on a block?, list, role of the fact, about ?x or the support ?y) -> consequence
_CONSEQUENCE: dict[tuple[str, bool, str, str, str], str] = {
    (PICK, False, "pre", "hand_empty", "-"): "the arm could pick up a block while holding one",
    (PICK, True, "pre", "hand_empty", "-"): "the arm could pick up a block while holding one",
    (PICK, False, "pre", "clear", "x"): "a block could be picked up from under another",
    (PICK, True, "pre", "clear", "x"): "a block could be taken from under another",
    (PICK, False, "pre", "on_table", "x"): "a block could be picked up from where it is not",
    (PICK, True, "pre", "on", "x"): "a block could be taken from a block it is not on",
    (PICK, False, "del", "hand_empty", "-"): "the arm would still count as empty while holding",
    (PICK, True, "del", "hand_empty", "-"): "the arm would still count as empty while holding",
    (PICK, False, "del", "on_table", "x"): "a held block would still be on the table",
    (PICK, True, "del", "on", "x"): "a held block would still sit on the block below",
    (PICK, False, "del", "clear", "x"): "a held block would count as clear, so one could be "
    "stacked on it",
    (PICK, True, "del", "clear", "x"): "a held block would count as clear, so one could be "
    "stacked on it",
    (PICK, False, "add", "holding", "x"): "nothing would be held",
    (PICK, True, "add", "holding", "x"): "nothing would be held",
    (PICK, True, "add", "clear", "y"): "the block below would never be clear again",
    (PLACE, False, "pre", "holding", "x"): "a block could be put down without being held",
    (PLACE, True, "pre", "holding", "x"): "a block could be stacked without being held",
    (PLACE, True, "pre", "clear", "y"): "a block could be stacked on one that carries another",
    (PLACE, False, "del", "holding", "x"): "the arm would still hold the block it put down",
    (PLACE, True, "del", "holding", "x"): "the arm would still hold the block it stacked",
    (PLACE, True, "del", "clear", "y"): "a block could then carry two blocks",
    (PLACE, False, "add", "clear", "x"): "a block put down could never be picked up or built "
    "on again",
    (PLACE, True, "add", "clear", "x"): "a stacked block could never be picked up or built "
    "on again",
    (PLACE, False, "add", "hand_empty", "-"): "the arm could never pick up again",
    (PLACE, True, "add", "hand_empty", "-"): "the arm could never pick up again",
    (PLACE, False, "add", "on_table", "x"): "the block put down would be nowhere",
    (PLACE, True, "add", "on", "x"): "the stacked block would be nowhere",
}

_LIST_WORDS = {"pre": "lacks the precondition", "add": "does not add", "del": "does not delete"}
_EXTRA_WORDS = {"pre": "has the extra precondition", "add": "also adds", "del": "also deletes"}


@dataclass(frozen=True)
class Difference:
    """One way an action schema differs from its Blocksworld meaning."""

    action: str
    text: str  # "does not delete (clear ?y)"
    consequence: str

    def __str__(self) -> str:
        return f"{self.action} {self.text}: {self.consequence}"


@dataclass(frozen=True)
class Witness:
    """The shortest run where the domain and textbook Blocksworld disagree."""

    plan: tuple[GroundAction, ...]  # in the domain's own names
    what: str  # what goes wrong after (or at) the last action

    def __str__(self) -> str:
        steps = " ".join(str(a) for a in self.plan) or "(no action)"
        return f"from a, b, c on the table: {steps}: {self.what}"


@dataclass
class DomainCheck:
    """What :func:`check_domain` found; ``ok`` when the domain means Blocksworld."""

    path: str
    vocabulary: Vocabulary | None
    differences: list[Difference] = field(default_factory=list)
    witness: Witness | None = None

    @property
    def ok(self) -> bool:
        return not self.differences and self.witness is None

    def lines(self) -> list[str]:
        """The report, one finding a line."""
        if self.ok:
            return [f"{self.path}: the four actions mean textbook Blocksworld"]
        out = [f"{self.path}: {d}" for d in self.differences]
        if self.witness is not None:
            out.append(f"{self.path}: shortest witness: {self.witness}")
        return out


# --------------------------------------------------------------------------- per action


@dataclass(frozen=True)
class _Reading:
    kind: str
    x: str
    y: str | None
    pre: frozenset[Fact]
    add: frozenset[Fact]
    delete: frozenset[Fact]


def _read(a: ActionSchema, v: Vocabulary) -> _Reading | None:
    """What ``a`` should be, judged from the holding fact it adds or deletes."""
    picked = [f for f in a.add if f[0] == v.holding]
    released = [f for f in a.delete if f[0] == v.holding]
    if len(picked) + len(released) != 1:
        # a place that forgets to delete holding is still read by its (hand empty) add
        if not picked and not released:
            if (v.hand_empty,) in a.add or any(f[0] == v.on for f in a.add):
                on = [f for f in a.add if f[0] in (v.on, v.on_table)]
                if on:
                    released = [(v.holding, on[0][1])]
            elif (v.hand_empty,) in a.delete:
                gone = [f for f in a.delete if f[0] in (v.on, v.on_table)]
                if gone:
                    picked = [(v.holding, gone[0][1])]
        if len(picked) + len(released) != 1:
            return None
    if picked:
        x = picked[0][1]
        moved = [f for f in a.delete if f[0] == v.on and f[1] == x]
        moved = moved or [f for f in a.pre if f[0] == v.on and f[1] == x]
        y = moved[0][2] if moved else None
        pre = {(v.clear, x), (v.hand_empty,)}
        pre |= {(v.on_table, x)} if y is None else {(v.on, x, y)}
        add = {(v.holding, x)} | (set() if y is None else {(v.clear, y)})
        return _Reading(PICK, x, y, frozenset(pre), frozenset(add), frozenset(pre))
    x = released[0][1]
    moved = [f for f in a.add if f[0] == v.on and f[1] == x]
    y = moved[0][2] if moved else None
    if y is None and len(a.params) == 2:
        y = next(p for p, _ in a.params if p != x)
    pre = {(v.holding, x)} | (set() if y is None else {(v.clear, y)})
    add = {(v.clear, x), (v.hand_empty,)}
    add |= {(v.on_table, x)} if y is None else {(v.on, x, y)}
    return _Reading(PLACE, x, y, frozenset(pre), frozenset(add), frozenset(pre))


def _role_of(fact: Fact, v: Vocabulary, r: _Reading) -> tuple[str, str]:
    role = next((k for k, name in v.as_dict().items() if name == fact[0]), fact[0])
    about = "-" if len(fact) == 1 else ("x" if fact[1] == r.x else "y")
    return role, about


def _generic(listing: str, role: str, missing: bool) -> str:
    if missing:
        return {
            "pre": "the action could run where Blocksworld forbids it",
            "add": "a fact that becomes true would stay false",
            "del": "a fact that becomes false would stay true",
        }[listing]
    return {
        "pre": "the action could not run in some states where Blocksworld allows it",
        "add": "a fact that is false would be made true",
        "del": "a fact that stays true would be made false",
    }[listing]


def _action_differences(a: ActionSchema, v: Vocabulary) -> list[Difference]:
    r = _read(a, v)
    if r is None:
        return [
            Difference(
                a.name,
                f"neither picks up nor puts down one block (it adds and deletes no "
                f"single ({v.holding} ...) fact)",
                "the robot cannot execute it",
            )
        ]
    on_block = r.y is not None
    found: list[Difference] = []
    params = [p for p, _ in a.params]
    used = [r.x] + ([r.y] if r.y is not None else [])
    for p in used:
        if p not in params:
            found.append(Difference(a.name, f"names {p}, not a parameter", "it cannot be ground"))
    for p in params:
        if p not in used:
            found.append(
                Difference(
                    a.name,
                    f"has parameter {p}, neither the block nor its support",
                    "the planner must choose an object that changes nothing",
                )
            )
    actual = {"pre": set(a.pre), "add": set(a.add), "del": set(a.delete)}
    expected = {"pre": r.pre, "add": r.add, "del": r.delete}
    for listing in ("pre", "add", "del"):
        for f in sorted(expected[listing] - actual[listing]):
            role, about = _role_of(f, v, r)
            why = _CONSEQUENCE.get((r.kind, on_block, listing, role, about))
            found.append(
                Difference(
                    a.name,
                    f"{_LIST_WORDS[listing]} {fact_str(f)}",
                    why or _generic(listing, role, True),
                )
            )
    for listing in ("pre", "add", "del"):
        for f in sorted(actual[listing] - expected[listing]):
            if listing == "pre" and f[0] not in v.as_dict().values():
                continue  # a static precondition such as (block ?x) restricts, moves nothing
            found.append(
                Difference(
                    a.name, f"{_EXTRA_WORDS[listing]} {fact_str(f)}", _generic(listing, "", False)
                )
            )
    return found


# --------------------------------------------------------------------------- witness


def _ground(a: ActionSchema, args: tuple[str, ...]):
    binding = {p: o for (p, _), o in zip(a.params, args, strict=True)}

    def bind(fs: Iterable[Fact]) -> frozenset[Fact]:
        return frozenset(tuple(binding.get(t, t) for t in f) for f in fs)

    return bind(a.pre), bind(a.add), bind(a.delete)


def _textbook(state: frozenset[Fact], kind: str, x: str, y: str | None):
    """The textbook action's effect on a canonical state, or None if it is not applicable."""
    c = CANONICAL
    r = _Reading(
        kind,
        x,
        y,
        *(
            (
                frozenset({(c.clear, x), (c.hand_empty,), (c.on_table, x)}),
                frozenset({(c.holding, x)}),
                frozenset({(c.clear, x), (c.hand_empty,), (c.on_table, x)}),
            )
            if kind == PICK and y is None
            else (
                frozenset({(c.clear, x), (c.hand_empty,), (c.on, x, y)}),
                frozenset({(c.holding, x), (c.clear, y)}),
                frozenset({(c.clear, x), (c.hand_empty,), (c.on, x, y)}),
            )
            if kind == PICK
            else (
                frozenset({(c.holding, x)}),
                frozenset({(c.clear, x), (c.hand_empty,), (c.on_table, x)}),
                frozenset({(c.holding, x)}),
            )
            if y is None
            else (
                frozenset({(c.holding, x), (c.clear, y)}),
                frozenset({(c.clear, x), (c.hand_empty,), (c.on, x, y)}),
                frozenset({(c.holding, x), (c.clear, y)}),
            )
        ),
    )
    if x == y or not r.pre <= state:
        return None
    return (state - r.delete) | r.add


def _textbook_pre(kind: str, x: str, y: str | None) -> frozenset[Fact]:
    c = CANONICAL
    if kind == PICK:
        where = (c.on_table, x) if y is None else (c.on, x, y)
        return frozenset({(c.clear, x), (c.hand_empty,), where})
    return frozenset({(c.holding, x)} | (set() if y is None else {(c.clear, y)}))


def _physical_error(said: frozenset[Fact]) -> str:
    """What no real table can show: a block carrying two, an arm holding two."""
    c = CANONICAL
    on_top: dict[str, list[str]] = {}
    for f in said:
        if f[0] == c.on:
            on_top.setdefault(f[2], []).append(f[1])
    for below, above in sorted(on_top.items()):
        if len(above) > 1:
            return f"{below} carries {' and '.join(sorted(above))} at once"
    held = sorted(f[1] for f in said if f[0] == c.holding)
    if len(held) > 1:
        return f"the arm holds {' and '.join(held)} at once"
    return ""


def _describe_state_error(true: frozenset[Fact], said: frozenset[Fact]) -> str:
    physical = _physical_error(said)
    if physical:
        return physical
    wrong = sorted(said - true)
    lost = sorted(true - said)
    parts = []
    if wrong:
        parts.append(f"the domain says {', '.join(fact_str(f) for f in wrong)}: false")
    if lost:
        parts.append(f"it lacks {', '.join(fact_str(f) for f in lost)}: true")
    return "; ".join(parts)


def find_witness(domain: Domain, v: Vocabulary) -> Witness | None:
    """Breadth-first, the shortest run where ``domain`` and textbook Blocksworld disagree."""
    readings = {a.name: _read(a, v) for a in domain.actions.values()}
    to_canon = {name: getattr(CANONICAL, role) for role, name in v.as_dict().items()}
    blocks = WITNESS_BLOCKS

    def canon(state: frozenset[Fact]) -> frozenset[Fact]:
        return frozenset((to_canon[f[0]], *f[1:]) for f in state if f[0] in to_canon)

    def own(facts: Iterable[Fact]) -> frozenset[Fact]:
        back = {n: own_name for own_name, n in to_canon.items()}
        return frozenset((back[f[0]], *f[1:]) for f in facts)

    true0 = frozenset(
        {(CANONICAL.hand_empty,)}
        | {(CANONICAL.on_table, b) for b in blocks}
        | {(CANONICAL.clear, b) for b in blocks}
    )
    # static predicates (e.g. (block ?x)) hold of every block
    statics = {
        p.name
        for p in domain.predicates.values()
        if p.name in domain.static_predicates and p.arity == 1
    }
    start = own(true0) | {(s, b) for s in statics for b in blocks}
    # Kinds of disagreement, best first: an action the domain allows and Blocksworld forbids
    # that leaves a state no table can show (a block carrying two, an arm holding two); any
    # such forbidden action (both: plans exploiting the bug); an action Blocksworld allows
    # and the domain forbids; a state the domain describes wrongly. Each kind keeps its
    # shortest instance; the search stops at the first of the best kind.
    found: dict[int, Witness] = {}
    seen = {(start, true0)}
    queue: deque[tuple[frozenset[Fact], frozenset[Fact], tuple[GroundAction, ...]]] = deque(
        [(start, true0, ())]
    )
    while queue and 0 not in found:
        state, true, plan = queue.popleft()
        if len(plan) >= WITNESS_DEPTH:
            continue
        allowed: set[GroundAction] = set()
        steps = []
        for a in sorted(domain.actions.values(), key=lambda s: s.name):
            r = readings[a.name]
            if r is None:
                continue
            for args in itertools.product(blocks, repeat=len(a.params)):
                pre, add, delete = _ground(a, args)
                if not pre <= state:
                    continue
                binding = dict(zip((p for p, _ in a.params), args, strict=True))
                x = binding.get(r.x, r.x)
                y = None if r.y is None else binding.get(r.y, r.y)
                allowed.add(canonical_action(r.kind, x, y))
                ground = GroundAction(a.name, tuple(args))
                after = (state - delete) | add
                after_true = _textbook(true, r.kind, x, y)
                if after_true is None:
                    unmet = sorted(_textbook_pre(r.kind, x, y) - true)
                    why = ", ".join(sorted(fact_str(f) for f in own(unmet)))
                    why += " is" if len(unmet) == 1 else " are"
                    problem = _physical_error(canon(after))
                    found.setdefault(
                        0 if problem else 1,
                        Witness(
                            (*plan, ground),
                            f"Blocksworld forbids {ground} there ({why} false)"
                            + (f"; after it {problem}" if problem else ""),
                        ),
                    )
                    continue
                steps.append((ground, after, after_true))
        if 2 not in found:
            for kind, on_block in ((PICK, False), (PICK, True), (PLACE, False), (PLACE, True)):
                for x in blocks:
                    for y in blocks if on_block else (None,):
                        meaning = canonical_action(kind, x, y)
                        if _textbook(true, kind, x, y) is not None and meaning not in allowed:
                            found.setdefault(
                                2,
                                Witness(
                                    plan,
                                    f"the domain cannot do {meaning}, which Blocksworld "
                                    "allows there",
                                ),
                            )
        for ground, after, after_true in steps:
            if 3 not in found:
                problem = _describe_state_error(after_true, canon(after))
                if problem:
                    found[3] = Witness((*plan, ground), problem)
            if (after, after_true) not in seen:
                seen.add((after, after_true))
                queue.append((after, after_true, (*plan, ground)))
    return found[min(found)] if found else None


# --------------------------------------------------------------------------- entry


def check_domain(domain: Domain) -> DomainCheck:
    """Compare ``domain``'s schemas with Blocksworld's; see the module docstring."""
    try:
        v = _read_vocabulary(domain)
    except _NotBlocksworld as e:
        return DomainCheck(
            domain.path,
            None,
            [Difference("the domain", "cannot be read as Blocksworld", str(e))],
        )
    report = DomainCheck(domain.path, v)
    for a in domain.actions.values():
        report.differences.extend(_action_differences(a, v))
    kinds = set()
    for a in domain.actions.values():
        r = _read(a, v)
        if r is not None:
            kinds.add((r.kind, r.y is not None))
    for kind, on_block in sorted(
        {(PICK, False), (PICK, True), (PLACE, False), (PLACE, True)} - kinds
    ):
        what = canonical_action(kind, "?x", "?y" if on_block else None).name
        report.differences.append(
            Difference(
                "the domain",
                f"has no action that does what {what} does",
                "some towers could never be built or taken apart",
            )
        )
    report.witness = find_witness(domain, v)
    return report


def is_textbook(domain: Domain) -> bool:
    """True when ``domain`` reads as Blocksworld with no difference (cheap for plan's warning)."""
    return check_domain(domain).ok


def looks_like_blocksworld(domain: Domain) -> bool:
    """True when ``domain``'s vocabulary reads as Blocksworld's (so a check is meaningful)."""
    try:
        _read_vocabulary(domain)
    except _NotBlocksworld:
        return False
    return True
