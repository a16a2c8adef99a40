"""Blocksworld helpers: towers, state consistency, problem generators.

The helpers work on facts in any Blocksworld vocabulary (default: the canonical
names ``on``, ``on-table``, ``clear``, ``holding``, ``arm-empty``; pass a
domain's :class:`~cake_drake.symbolic.roles.Vocabulary` for its own names, and
the messages use them too). The world layer places cubes with :func:`towers`;
:func:`check_state` says in plain words what is wrong with a set of facts that
is not a physical arrangement. :func:`random_problem` writes seeded problems in
the exercise's naming, the IPC naming or the typed one (:data:`NAMINGS`), with
tall towers and partial goals on request.
"""

from __future__ import annotations

import random
import string
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from cake_drake.errors import InputError
from cake_drake.paths import MODELS_DIR
from cake_drake.symbolic.pddl import Domain, Fact
from cake_drake.symbolic.roles import CANONICAL, Vocabulary, block_key
from cake_drake.symbolic.roles import is_blocksworld as _is_blocksworld

#: The canonical predicates (with arities), the names the world and geometry use.
BLOCKSWORLD_PREDICATES = {"on": 2, "on-table": 1, "clear": 1, "holding": 1, "arm-empty": 0}


def is_blocksworld(domain: Domain) -> bool:
    """True when ``domain`` is a Blocksworld domain by structure, whatever its names.

    See :func:`cake_drake.symbolic.roles.blocksworld_roles`, which also says why not.
    """
    return _is_blocksworld(domain)


def _canonical(facts: Iterable[Fact], v: Vocabulary) -> list[Fact]:
    """Rename ``v``'s predicates to the canonical ones (other facts pass unchanged)."""
    if v == CANONICAL:
        return list(facts)
    rename = {getattr(v, role): getattr(CANONICAL, role) for role in v.as_dict()}
    return [(rename.get(f[0], f"<{f[0]}>"), *f[1:]) for f in facts]


def _index(facts: Iterable[Fact]):
    on: dict[str, list[str]] = {}  # block -> what it is on (should be one)
    under: dict[str, list[str]] = {}  # block -> blocks on it (should be at most one)
    table: set[str] = set()
    clear: set[str] = set()
    held: list[str] = []
    arm_empty = False
    for f in facts:
        if f[0] == "on" and len(f) == 3:
            on.setdefault(f[1], []).append(f[2])
            under.setdefault(f[2], []).append(f[1])
        elif f[0] == "on-table" and len(f) == 2:
            table.add(f[1])
        elif f[0] == "clear" and len(f) == 2:
            clear.add(f[1])
        elif f[0] == "holding" and len(f) == 2:
            held.append(f[1])
        elif f == ("arm-empty",):
            arm_empty = True
    for x in (*on.values(), *under.values()):
        x.sort()
    held.sort()
    return on, under, table, clear, held, arm_empty


def _supports(block: str, on, table, held, v: Vocabulary) -> list[str]:
    s = [f"({v.on} {block} {y})" for y in on.get(block, [])]
    if block in table:
        s.append(f"({v.on_table} {block})")
    if block in held:
        s.append(f"({v.holding} {block})")
    return s


def _cycles(on: dict[str, list[str]]) -> list[list[str]]:
    """Groups of blocks whose chain of ``on`` facts loops instead of reaching the table."""
    found: list[list[str]] = []
    done: set[str] = set()
    for start in sorted(on):
        path: list[str] = []
        x = start
        while x in on and len(on[x]) == 1 and x not in done and x not in path:
            path.append(x)
            x = on[x][0]
        if x in path:
            found.append(path[path.index(x) :])
        done.update(path)
    return found


def _structure_problems(facts: list[Fact], v: Vocabulary) -> list[str]:
    """Contradictions any partial Blocksworld state (e.g. a goal) must not contain.

    ``facts`` are canonical; the messages use ``v``'s names.
    """
    on, under, table, clear, held, arm_empty = _index(facts)
    msgs = []
    for x in sorted(set(on) | table | set(held)):
        if x in on.get(x, []):
            msgs.append(f"{x} sits on itself: ({v.on} {x} {x})")
        s = _supports(x, on, table, held, v)
        if len(s) > 1:
            msgs.append(f"{x} has {len(s)} supports: {' '.join(s)}")
    for y in sorted(under):
        if len(under[y]) > 1:
            msgs.append(f"{y} has {len(under[y])} blocks on it: {', '.join(under[y])}")
        if y in clear:
            msgs.append(f"{y} has {under[y][0]} on it but ({v.clear} {y}) holds")
        if y in held:
            msgs.append(f"{y} is held but has {under[y][0]} on it")
    for x in held:
        if x in clear:
            msgs.append(f"{x} is held but ({v.clear} {x}) holds (picking a block up deletes it)")
    if len(held) > 1:
        msgs.append(f"the arm holds {len(held)} blocks at once: {', '.join(held)}")
    if held and arm_empty:
        msgs.append(f"({v.hand_empty}) and ({v.holding} {held[0]}) both hold")
    for cyc in _cycles(on):
        if len(cyc) > 1:
            pairs = zip(cyc, [*cyc[1:], cyc[0]], strict=True)
            chain = " ".join(f"({v.on} {a} {b})" for a, b in pairs)
            msgs.append(f"{', '.join(cyc)} stand on each other in a loop: {chain}")
    return msgs


def check_state(
    facts: Iterable[Fact], blocks: Iterable[str], vocabulary: Vocabulary = CANONICAL
) -> list[str]:
    """Consistency problems of a complete Blocksworld state, in plain words.

    Every block must have exactly one support (a block, the table or the
    arm); ``clear`` must hold exactly for the blocks with nothing on them that
    are not held; exactly one of ``(arm-empty)`` / ``(holding x)`` holds.
    ``facts`` and the messages use ``vocabulary``'s predicate names. An empty
    list means the facts describe a physical arrangement.
    """
    v = vocabulary
    facts = _canonical(facts, v)
    blocks = sorted(set(blocks))
    on, under, table, clear, held, arm_empty = _index(facts)
    msgs = _structure_problems(facts, v)
    known = set(blocks)
    mentioned = set(on) | set(under) | table | clear | set(held)
    for x in sorted(mentioned - known):
        msgs.append(f"{x} appears in the state but is not one of the blocks ({', '.join(blocks)})")
    for x in blocks:
        if not _supports(x, on, table, held, v):
            msgs.append(
                f"{x} rests on nothing: none of ({v.on_table} {x}), ({v.on} {x} ...), "
                f"({v.holding} {x}) holds"
            )
        if x not in under and x not in held and x not in clear:
            msgs.append(f"{x} has nothing on it but ({v.clear} {x}) is missing")
    if not held and not arm_empty:
        msgs.append(f"the arm is neither empty nor holding a block: ({v.hand_empty}) is missing")
    return msgs


def check_goal(goal: Iterable[Fact], vocabulary: Vocabulary = CANONICAL) -> list[str]:
    """Contradictions inside a (partial) Blocksworld goal, which make it unreachable."""
    return _structure_problems(_canonical(goal, vocabulary), vocabulary)


def towers(facts: Iterable[Fact], vocabulary: Vocabulary = CANONICAL) -> list[list[str]]:
    """The towers described by ``on`` / ``on-table`` facts, each listed bottom to top.

    Towers are ordered by the name of their bottom block (``b2`` before
    ``b10``). Other facts are
    ignored (a held block is in no tower). Raises :class:`InputError` when the
    facts are not a set of towers (two supports, two blocks on one, a loop, a
    block resting on nothing).
    """
    facts = [f for f in _canonical(facts, vocabulary) if f[0] in ("on", "on-table")]
    on, under, table, _, _, _ = _index(facts)
    problems = _structure_problems(facts, vocabulary)
    if problems:
        raise InputError("the facts are not a set of towers: " + "; ".join(problems))
    result = []
    placed = set()
    for bottom in sorted(table, key=block_key):
        tower = [bottom]
        while tower[-1] in under:
            tower.append(under[tower[-1]][0])
        placed.update(tower)
        result.append(tower)
    floating = sorted(set(on) - placed)
    if floating:
        raise InputError(
            "the facts are not a set of towers: "
            f"{', '.join(floating)} not on the table nor on a block that is"
        )
    return result


def tower_facts(stacks: Sequence[Sequence[str]], vocabulary: Vocabulary = CANONICAL) -> list[Fact]:
    """``on`` / ``on-table`` facts for towers given bottom to top."""
    v = vocabulary
    facts: list[Fact] = []
    for tower in stacks:
        if tower:
            facts.append((v.on_table, tower[0]))
            facts.extend((v.on, top, below) for below, top in zip(tower, tower[1:], strict=False))
    return facts


# --------------------------------------------------------------------------- generators


_VARIANTS = MODELS_DIR / "pddl" / "variants"


@dataclass(frozen=True)
class Naming:
    """How a family of published problems names things: domain, predicates, objects."""

    name: str
    domain_name: str
    domain_file: Path  # the shipped domain these problems are written for
    vocabulary: Vocabulary
    numbered: bool  # objects b1, b2, ... (else a, b, c, ... up to 26 blocks)
    block_type: str | None = None  # typed objects: "b1 b2 - block"


#: The namings :func:`random_problem` and :func:`blocks_problem` can write.
NAMINGS: dict[str, Naming] = {
    n.name: n
    for n in (
        Naming(
            "exercise", "blocksworld", MODELS_DIR / "pddl" / "blocksworld.pddl", CANONICAL, False
        ),
        Naming(
            "ipc",
            "blocks",
            _VARIANTS / "blocksworld-ipc.pddl",
            Vocabulary("on", "ontable", "clear", "holding", "handempty"),
            True,
        ),
        Naming(
            "typed",
            "blocks-typed",
            _VARIANTS / "blocksworld-typed.pddl",
            Vocabulary("on", "ontable", "clear", "holding", "handempty"),
            True,
            "block",
        ),
    )
}


def naming(name: str | Naming) -> Naming:
    """The :class:`Naming` called ``name``; :class:`InputError` listing the choices otherwise."""
    if isinstance(name, Naming):
        return name
    try:
        return NAMINGS[name]
    except KeyError:
        raise InputError(f"unknown naming '{name}' (choose from: {', '.join(NAMINGS)})") from None


def block_names(n_blocks: int, style: str | Naming = "exercise") -> list[str]:
    """``a``, ``b``, ... for up to 26 blocks (``b01``, ``b02``, ... beyond); with a
    numbered naming (``ipc``, ``typed``) ``b1``, ``b2``, ... as IPC problems write them."""
    if naming(style).numbered:
        return [f"b{i}" for i in range(1, n_blocks + 1)]
    if n_blocks <= 26:
        return list(string.ascii_lowercase[:n_blocks])
    width = len(str(n_blocks))
    return [f"b{i:0{width}d}" for i in range(1, n_blocks + 1)]


def problem_text(
    name: str,
    init_towers: Sequence[Sequence[str]],
    goal: Iterable[Fact],
    style: str | Naming = "exercise",
) -> str:
    """PDDL text of a problem: towers (bottom to top) with the arm empty, to ``goal``.

    ``goal`` is a list of canonical facts (any subset of a state: a partial goal
    is fine); they are written in ``style``'s names.
    """
    n = naming(style)
    v = n.vocabulary
    blocks = sorted({b for t in init_towers for b in t}, key=block_key)
    rename = {getattr(CANONICAL, r): getattr(v, r) for r in v.as_dict()}

    def fmt(facts: Iterable[Fact]) -> str:
        return " ".join("(" + " ".join((rename[f[0]], *f[1:])) + ")" for f in facts)

    init = tower_facts(init_towers) + [("clear", t[-1]) for t in init_towers if t]
    objects = " ".join(blocks) + (f" - {n.block_type}" if n.block_type else "")
    return (
        f"(define (problem {name})\n"
        f"  (:domain {n.domain_name})\n"
        f"  (:objects {objects})\n"
        f"  (:init {fmt(init)} ({v.hand_empty}))\n"
        f"  (:goal (and {fmt(goal)})))\n"
    )


def blocks_problem(
    name: str,
    init_towers: Sequence[Sequence[str]],
    goal_towers: Sequence[Sequence[str]],
    style: str | Naming = "exercise",
) -> str:
    """PDDL text of a Blocksworld problem from towers (bottom to top), arm empty.

    The goal states the position of every block named in ``goal_towers``.
    """
    return problem_text(name, init_towers, tower_facts(goal_towers), style)


def random_towers(
    blocks: Sequence[str], rng: random.Random, max_height: int | None = None, tall: bool = False
) -> list[list[str]]:
    """A seeded random split of ``blocks`` into towers (bottom to top).

    Each block in shuffled order starts a new tower with probability 1/2 (0.1
    when ``tall``) or goes on top of a random tower lower than ``max_height``.
    """
    order = list(blocks)
    rng.shuffle(order)
    p_new = 0.1 if tall else 0.5
    result: list[list[str]] = []
    for b in order:
        if not result or rng.random() < p_new:
            result.append([b])  # start a new tower
            continue
        low = result if max_height is None else [t for t in result if len(t) < max_height]
        if low:
            rng.choice(low).append(b)
        else:
            result.append([b])
    return sorted(result)


def partial_goal(goal_towers: Sequence[Sequence[str]], rng: random.Random) -> list[Fact]:
    """An IPC-style partial goal: about half of the towers' ``on`` facts, nothing else.

    At least one fact is kept (an ``on-table`` fact when the towers have no ``on``).
    """
    ons = [f for f in tower_facts(goal_towers) if f[0] == "on"]
    kept = [f for f in ons if rng.random() < 0.5]
    if not kept:
        kept = [rng.choice(ons)] if ons else [("on-table", rng.choice(goal_towers)[0])]
    return sorted(kept)


def random_problem(
    n_blocks: int,
    seed: int = 0,
    style: str | Naming = "exercise",
    *,
    tall: bool = False,
    max_height: int | None = None,
    goal_max_height: int | None = None,
    partial: bool = False,
) -> str:
    """A seeded random n-block problem as PDDL text: random towers to random towers.

    ``style`` names things as the exercise (``a``, ``b``, ...; ``on-table``,
    ``arm-empty``), the IPC (``b1``, ``b2``, ...; ``ontable``, ``handempty``) or
    the typed variant does (:data:`NAMINGS`); pair the text with
    ``NAMINGS[style].domain_file``. ``tall`` builds few, tall towers (start and
    goal); ``max_height`` / ``goal_max_height`` cap the towers' heights;
    ``partial`` keeps about half of the goal's ``on`` facts and no ``on-table``
    fact, as IPC problems do. The same arguments always give the same text.
    """
    if not isinstance(n_blocks, int) or n_blocks < 1:
        raise InputError(f"number of blocks must be a positive integer, got {n_blocks!r}")
    for what, h in (("max_height", max_height), ("goal_max_height", goal_max_height)):
        if h is not None and (not isinstance(h, int) or h < 1):
            raise InputError(f"{what} must be a positive integer, got {h!r}")
    rng = random.Random(f"blocksworld-{n_blocks}-{seed}")
    n = naming(style)
    blocks = block_names(n_blocks, n)
    init = random_towers(blocks, rng, max_height, tall)
    goal_towers = random_towers(blocks, rng, goal_max_height, tall)
    goal = partial_goal(goal_towers, rng) if partial else tower_facts(goal_towers)
    name = f"random-{n_blocks}-blocks-seed-{seed}"
    name += "-tall" * tall + "-partial" * partial
    return problem_text(name, init, goal, n)


def suite_problems(
    sizes: Iterable[int] = range(3, 13), seeds: Iterable[int] = (0, 1, 2)
) -> list[tuple[str, Naming, str]]:
    """The benchmark suite: ``(name, naming, PDDL text)`` for every size and seed.

    Seed 0 is the exercise's naming with random towers and a complete goal;
    seed 1 the IPC naming with tall towers (start up to 10 high, goal up to 9)
    and a partial goal; seed 2 the typed naming with random towers capped at
    10 and 9 and a partial goal; further seeds cycle through the three.
    """
    out = []
    for n in sizes:
        for seed in seeds:
            kind = seed % 3
            style = NAMINGS[("exercise", "ipc", "typed")[kind]]
            text = random_problem(
                n,
                seed,
                style,
                tall=kind == 1,
                max_height=10,
                goal_max_height=9,
                partial=kind > 0,
            )
            out.append((f"{style.name}-{n}-{seed}", style, text))
    return out
