"""Blocksworld-specific helpers: towers, state consistency, random problems.

The world layer places cubes with :func:`towers` and reads measured poses back
as ``on`` / ``on-table`` / ``clear`` facts; :func:`check_state` says in plain
words what is wrong with a set of facts that is not a physical arrangement.
"""

from __future__ import annotations

import random
import string
from collections.abc import Iterable, Sequence

from cake_drake.errors import InputError
from cake_drake.symbolic.pddl import Domain, Fact

#: The predicates (with arities) a domain needs for the Blocksworld checks to apply.
BLOCKSWORLD_PREDICATES = {"on": 2, "on-table": 1, "clear": 1, "holding": 1, "arm-empty": 0}


def is_blocksworld(domain: Domain) -> bool:
    """True when ``domain`` declares the five Blocksworld predicates with their arities."""
    return all(
        p in domain.predicates and domain.predicates[p].arity == n
        for p, n in BLOCKSWORLD_PREDICATES.items()
    )


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
    for v in (*on.values(), *under.values()):
        v.sort()
    held.sort()
    return on, under, table, clear, held, arm_empty


def _supports(block: str, on, table, held) -> list[str]:
    s = [f"(on {block} {y})" for y in on.get(block, [])]
    if block in table:
        s.append(f"(on-table {block})")
    if block in held:
        s.append(f"(holding {block})")
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


def _structure_problems(facts: Iterable[Fact]) -> list[str]:
    """Contradictions any partial Blocksworld state (e.g. a goal) must not contain."""
    on, under, table, clear, held, arm_empty = _index(facts)
    msgs = []
    for x in sorted(set(on) | table | set(held)):
        if x in on.get(x, []):
            msgs.append(f"{x} sits on itself: (on {x} {x})")
        s = _supports(x, on, table, held)
        if len(s) > 1:
            msgs.append(f"{x} has {len(s)} supports: {' '.join(s)}")
    for y in sorted(under):
        if len(under[y]) > 1:
            msgs.append(f"{y} has {len(under[y])} blocks on it: {', '.join(under[y])}")
        if y in clear:
            msgs.append(f"{y} has {under[y][0]} on it but (clear {y}) holds")
        if y in held:
            msgs.append(f"{y} is held but has {under[y][0]} on it")
    for x in held:
        if x in clear:
            msgs.append(f"{x} is held but (clear {x}) holds (picking a block up deletes it)")
    if len(held) > 1:
        msgs.append(f"the arm holds {len(held)} blocks at once: {', '.join(held)}")
    if held and arm_empty:
        msgs.append(f"(arm-empty) and (holding {held[0]}) both hold")
    for cyc in _cycles(on):
        if len(cyc) > 1:
            chain = " ".join(f"(on {a} {b})" for a, b in zip(cyc, [*cyc[1:], cyc[0]], strict=True))
            msgs.append(f"{', '.join(cyc)} stand on each other in a loop: {chain}")
    return msgs


def check_state(facts: Iterable[Fact], blocks: Iterable[str]) -> list[str]:
    """Consistency problems of a complete Blocksworld state, in plain words.

    Every block must have exactly one support (a block, the table or the
    arm); ``clear`` must hold exactly for the blocks with nothing on them that
    are not held; exactly one of ``(arm-empty)`` / ``(holding x)`` holds.
    An empty list means the facts describe a physical arrangement.
    """
    facts = list(facts)
    blocks = sorted(set(blocks))
    on, under, table, clear, held, arm_empty = _index(facts)
    msgs = _structure_problems(facts)
    known = set(blocks)
    mentioned = set(on) | set(under) | table | clear | set(held)
    for x in sorted(mentioned - known):
        msgs.append(f"{x} appears in the state but is not one of the blocks ({', '.join(blocks)})")
    for x in blocks:
        if not _supports(x, on, table, held):
            msgs.append(
                f"{x} rests on nothing: none of (on-table {x}), (on {x} ...), (holding {x}) holds"
            )
        if x not in under and x not in held and x not in clear:
            msgs.append(f"{x} has nothing on it but (clear {x}) is missing")
    if not held and not arm_empty:
        msgs.append("the arm is neither empty nor holding a block: (arm-empty) is missing")
    return msgs


def check_goal(goal: Iterable[Fact]) -> list[str]:
    """Contradictions inside a (partial) Blocksworld goal, which make it unreachable."""
    return _structure_problems(goal)


def towers(facts: Iterable[Fact]) -> list[list[str]]:
    """The towers described by ``on`` / ``on-table`` facts, each listed bottom to top.

    Towers are ordered by the name of their bottom block. Other facts are
    ignored (a held block is in no tower). Raises :class:`InputError` when the
    facts are not a set of towers (two supports, two blocks on one, a loop, a
    block resting on nothing).
    """
    facts = [f for f in facts if f[0] in ("on", "on-table")]
    on, under, table, _, _, _ = _index(facts)
    problems = _structure_problems(facts)
    if problems:
        raise InputError("the facts are not a set of towers: " + "; ".join(problems))
    result = []
    placed = set()
    for bottom in sorted(table):
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


def block_names(n_blocks: int) -> list[str]:
    """``a``, ``b``, ... for up to 26 blocks; ``b01``, ``b02``, ... beyond."""
    if n_blocks <= 26:
        return list(string.ascii_lowercase[:n_blocks])
    width = len(str(n_blocks))
    return [f"b{i:0{width}d}" for i in range(1, n_blocks + 1)]


def tower_facts(stacks: Sequence[Sequence[str]]) -> list[Fact]:
    """``on`` / ``on-table`` facts for towers given bottom to top."""
    facts: list[Fact] = []
    for tower in stacks:
        if tower:
            facts.append(("on-table", tower[0]))
            facts.extend(("on", top, below) for below, top in zip(tower, tower[1:], strict=False))
    return facts


def blocks_problem(
    name: str, init_towers: Sequence[Sequence[str]], goal_towers: Sequence[Sequence[str]]
) -> str:
    """PDDL text of a Blocksworld problem from towers (bottom to top), arm empty.

    The goal states the position of every block named in ``goal_towers``.
    """
    blocks = sorted({b for t in init_towers for b in t})

    def fmt(facts: Iterable[Fact]) -> str:
        return " ".join("(" + " ".join(f) + ")" for f in facts)

    init = tower_facts(init_towers) + [("clear", t[-1]) for t in init_towers if t]
    goal = tower_facts(goal_towers)
    return (
        f"(define (problem {name})\n"
        "  (:domain blocksworld)\n"
        f"  (:objects {' '.join(blocks)})\n"
        f"  (:init {fmt(init)} (arm-empty))\n"
        f"  (:goal (and {fmt(goal)})))\n"
    )


def random_towers(blocks: Sequence[str], rng: random.Random) -> list[list[str]]:
    """A uniformly shuffled split of ``blocks`` into towers (bottom to top)."""
    order = list(blocks)
    rng.shuffle(order)
    result: list[list[str]] = []
    for b in order:
        if not result or rng.random() < 0.5:
            result.append([b])  # start a new tower
        else:
            rng.choice(result).append(b)
    return sorted(result)


def random_problem(n_blocks: int, seed: int = 0) -> str:
    """A seeded random n-block problem as PDDL text: random towers to random towers.

    The same ``(n_blocks, seed)`` always gives the same text.
    """
    if not isinstance(n_blocks, int) or n_blocks < 1:
        raise InputError(f"number of blocks must be a positive integer, got {n_blocks!r}")
    rng = random.Random(f"blocksworld-{n_blocks}-{seed}")
    blocks = block_names(n_blocks)
    init = random_towers(blocks, rng)
    goal = random_towers(blocks, rng)
    return blocks_problem(f"random-{n_blocks}-blocks-seed-{seed}", init, goal)
