"""Blocksworld read by structure: what each predicate and action *means*, whatever its name.

Published Blocksworld domains differ in their names (``pick-up`` or ``pickup``,
``on-table`` or ``ontable``, ``arm-empty`` or ``handempty``, typed or not) but
share one structure. :func:`blocksworld_roles` finds that structure in the
add and delete lists of the action schemas:

- **hand empty**: the one 0-ary predicate the actions change;
- **holding**: the one-argument predicate every action that deletes *hand
  empty* adds, and every action that adds *hand empty* deletes;
- **on**: the one two-argument predicate the actions change;
- **clear**: the one-argument predicate deleted for ``?y`` when ``(on ?x ?y)``
  is added, and added for ``?y`` when ``(on ?x ?y)`` is deleted;
- **on the table**: the remaining one-argument predicate the actions change.

Each action is then a **pick** (it adds ``(holding ?x)``: from the table if it
deletes ``(on-table ?x)``, from block ``?y`` if it deletes ``(on ?x ?y)``) or a
**place** (it deletes ``(holding ?x)``: onto the table if it adds
``(on-table ?x)``, onto ``?y`` if it adds ``(on ?x ?y)``), with exactly the
preconditions and effects of the standard four operators. Static predicates
(``(block ?x)`` in some untyped variants) may appear in preconditions: they
restrict, they do not move anything.

A domain that cannot be read this way, or that has an action that does
something else (the robot could not execute it), raises :class:`InputError`
with one line naming the domain file, the action or predicate, and what is
missing. Hand empty is required: without it a domain lets the arm hold two
blocks at once, which one gripper cannot do.

Inside the world and the geometry the **canonical** names are used:
``on``, ``on-table``, ``clear``, ``holding``, ``arm-empty``
(:data:`CANONICAL`); :meth:`BlocksworldRoles.to_canonical` and
:meth:`~BlocksworldRoles.from_canonical` translate at the boundary.
"""

from __future__ import annotations

import weakref
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, fields

from cake_drake.errors import InputError
from cake_drake.symbolic.pddl import ActionSchema, Domain, Fact, GroundAction, Problem, fact_str

PICK = "pick"
PLACE = "place"


@dataclass(frozen=True)
class Vocabulary:
    """The names one domain gives the five Blocksworld predicates."""

    on: str = "on"
    on_table: str = "on-table"
    clear: str = "clear"
    holding: str = "holding"
    hand_empty: str = "arm-empty"

    def as_dict(self) -> dict[str, str]:
        """Role -> predicate name, e.g. ``{"on_table": "ontable", ...}``."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


#: The names the world and the geometric layer use.
CANONICAL = Vocabulary()


@dataclass(frozen=True)
class ActionRole:
    """What an action schema does: ``kind`` is :data:`PICK` or :data:`PLACE`.

    ``block`` is the index of the parameter that ends up held (pick) or is
    released (place); ``support`` is the index of the other block's parameter
    (the block picked from, or placed on), None for the table.
    """

    kind: str
    block: int
    support: int | None

    def describe(self) -> str:
        """``"pick from the table"``, ``"place on a block"``, ..."""
        if self.kind == PICK:
            return "pick from " + ("the table" if self.support is None else "a block")
        return "place on " + ("the table" if self.support is None else "a block")


@dataclass(frozen=True)
class GroundRole:
    """What a ground action does: pick or place ``block``, from or onto ``support``.

    ``support`` is the other block's name, or None for the table.
    """

    action: GroundAction
    kind: str
    block: str
    support: str | None

    def canonical(self) -> GroundAction:
        """The same action in the exercise domain's names (``pick-up``, ``unstack``, ...)."""
        return canonical_action(self.kind, self.block, self.support)


def canonical_action(kind: str, block: str, support: str | None = None) -> GroundAction:
    """The exercise domain's action with this meaning: ``(stack a b)``, ``(pick-up a)``, ..."""
    if kind == PICK:
        return (
            GroundAction("pick-up", (block,))
            if support is None
            else GroundAction("unstack", (block, support))
        )
    if kind == PLACE:
        return (
            GroundAction("put-down", (block,))
            if support is None
            else GroundAction("stack", (block, support))
        )
    raise ValueError(f"kind must be {PICK!r} or {PLACE!r}, got {kind!r}")


@dataclass(frozen=True)
class BlocksworldRoles:
    """A Blocksworld domain read by structure: its vocabulary and what each action does."""

    domain: str  # the domain's name
    vocabulary: Vocabulary
    actions: Mapping[str, ActionRole]  # schema name -> role, in the domain's order
    block_types: tuple[str, ...]  # types of the block parameters (("object",) when untyped)

    @property
    def on(self) -> str:
        return self.vocabulary.on

    @property
    def on_table(self) -> str:
        return self.vocabulary.on_table

    @property
    def clear(self) -> str:
        return self.vocabulary.clear

    @property
    def holding(self) -> str:
        return self.vocabulary.holding

    @property
    def hand_empty(self) -> str:
        return self.vocabulary.hand_empty

    def _renaming(self, source: Vocabulary, target: Vocabulary) -> dict[str, str]:
        t = target.as_dict()
        return {name: t[role] for role, name in source.as_dict().items()}

    def to_canonical(self, facts: Iterable[Fact]) -> frozenset[Fact]:
        """``facts`` in the canonical names; facts of other (static) predicates are dropped.

        ``(ontable b1)`` -> ``("on-table", "b1")``, ``(handempty)`` -> ``("arm-empty",)``.
        Static facts such as ``(block b1)`` say nothing about where a block is.
        """
        rename = self._renaming(self.vocabulary, CANONICAL)
        return frozenset((rename[f[0]], *f[1:]) for f in facts if f[0] in rename)

    def from_canonical(self, facts: Iterable[Fact]) -> frozenset[Fact]:
        """Canonical facts (e.g. read back from the world) in this domain's names."""
        rename = self._renaming(CANONICAL, self.vocabulary)
        out = []
        for f in facts:
            if f[0] not in rename:
                raise InputError(
                    f"{fact_str(f)} is not a canonical Blocksworld fact "
                    f"(predicates: {', '.join(CANONICAL.as_dict().values())})"
                )
            out.append((rename[f[0]], *f[1:]))
        return frozenset(out)

    def classify(self, action: GroundAction) -> GroundRole:
        """Pick or place, which block, and which support (None for the table)."""
        role = self.actions.get(action.name)
        if role is None:
            raise InputError(
                f"{action}: no action '{action.name}' in domain '{self.domain}' "
                f"(actions: {', '.join(self.actions)})"
            )
        needed = max(role.block, -1 if role.support is None else role.support) + 1
        if len(action.args) < needed:
            raise InputError(f"{action}: action '{action.name}' takes {needed} arguments")
        support = None if role.support is None else action.args[role.support]
        return GroundRole(action, role.kind, action.args[role.block], support)

    def unpile(self, block: str, canonical) -> tuple[GroundAction, ...]:
        """This domain's actions that put the blocks on top of ``block`` on the table, the
        top one first, from the facts ``canonical`` (in the canonical names)."""
        above = {f[2]: f[1] for f in canonical if f[0] == "on"}
        chain = []
        top = block
        while top in above:
            chain.append((above[top], top))
            top = above[top]
        actions: list[GroundAction] = []
        for upper, lower in reversed(chain):
            actions += [self.action(PICK, upper, lower), self.action(PLACE, upper)]
        return tuple(actions)

    def action(self, kind: str, block: str, support: str | None = None) -> GroundAction:
        """This domain's ground action with a meaning: ``action("pick", "b1")`` -> ``(pickup b1)``.

        The first schema (in the domain's order) with that meaning is used.
        """
        for name, role in self.actions.items():
            if role.kind == kind and (role.support is None) == (support is None):
                args = [""] * (1 + (support is not None))
                args[role.block] = block
                if role.support is not None:
                    args[role.support] = support  # type: ignore[assignment]
                return GroundAction(name, tuple(args))
        what = ActionRole(kind, 0, None if support is None else 1).describe()
        raise InputError(f"domain '{self.domain}' has no action that does '{what}'")

    def blocks(self, problem: Problem) -> list[str]:
        """The problem's blocks: its objects (and constants) of a block parameter's type,
        in natural order (``b2`` before ``b10``)."""
        d = problem.domain
        return sorted(
            (
                o
                for o, t in problem.object_types.items()
                if any(d.is_subtype(t, bt) for bt in self.block_types)
            ),
            key=block_key,
        )


def block_key(name: str) -> tuple:
    """Sort key that puts ``b2`` before ``b10`` (and ``a``, ``b``, ``c`` in order)."""
    digits = name[len(name.rstrip("0123456789")) :]
    return (name[: len(name) - len(digits)], int(digits) if digits else -1, name)


# --------------------------------------------------------------------------- reading


class _NotBlocksworld(Exception):
    pass


def _fail(msg: str):
    raise _NotBlocksworld(msg)


def _f(*parts: str) -> str:
    return fact_str(tuple(parts))


def _fluents(domain: Domain) -> dict[str, tuple[str, int]]:
    """Predicate -> (first action changing it, arity), for every changed predicate."""
    found: dict[str, tuple[str, int]] = {}
    for a in domain.actions.values():
        for f in (*a.add, *a.delete):
            found.setdefault(f[0], (a.name, len(f) - 1))
    return found


def _only(candidates: Iterable[str], none: str, many: str) -> str:
    c = sorted(set(candidates))
    if not c:
        _fail(none)
    if len(c) > 1:
        _fail(many.format(", ".join(f"'{p}'" for p in c)))
    return c[0]


def _read_vocabulary(domain: Domain) -> Vocabulary:
    fluents = _fluents(domain)
    actions = list(domain.actions.values())
    for p, (a, arity) in fluents.items():
        if arity > 2:
            _fail(
                f"action '{a}' changes predicate '{p}' of {arity} arguments "
                "(Blocksworld predicates take at most two)"
            )
    by_arity = {n: [p for p, (_, k) in fluents.items() if k == n] for n in (0, 1, 2)}

    if not by_arity[0]:
        movers = [a.name for a in actions if any(len(f) == 3 for f in (*a.add, *a.delete))]
        lead = (
            f"action '{movers[0]}' moves a block in one step, never holding it; " if movers else ""
        )
        _fail(
            f"{lead}no action changes a 0-ary 'hand empty' predicate such as (handempty), "
            "so nothing picks a block up and puts it down"
        )
    hand_empty = _only(
        by_arity[0],
        "",
        "the actions change the 0-ary predicates {}; a Blocksworld domain has one, 'hand empty'",
    )
    grasp = [a for a in actions if (hand_empty,) in a.delete]
    release = [a for a in actions if (hand_empty,) in a.add]
    if not grasp:
        _fail(f"no action deletes ({hand_empty}): nothing picks a block up")
    if not release:
        _fail(f"no action adds ({hand_empty}): nothing puts a block down")
    unary = set(by_arity[1])
    held = set(unary)
    for a in grasp:
        held &= {f[0] for f in a.add if len(f) == 2}
    for a in release:
        held &= {f[0] for f in a.delete if len(f) == 2}
    holding = _only(
        held,
        f"no one-argument 'holding' predicate: no fact is added by every action that deletes "
        f"({hand_empty}) ({', '.join(a.name for a in grasp)}) and deleted by every action "
        f"that adds it ({', '.join(a.name for a in release)})",
        "cannot tell which of {} means 'holding'",
    )
    for a in actions:
        if not any(f[0] == holding for f in (*a.add, *a.delete)):
            _fail(
                f"action '{a.name}' neither picks up nor puts down a block "
                f"(it adds and deletes no ({holding} ...) fact)"
            )

    on = _only(
        by_arity[2],
        "no action changes a two-argument 'on' predicate: nothing stacks a block on another",
        "the actions change the two-argument predicates {}; a Blocksworld domain has one, 'on'",
    )
    stacking = [a for a in actions if any(f[0] == on for f in (*a.add, *a.delete))]
    clear_candidates = set()  # deleted for ?y by stacking on ?y, added for ?y by unstacking
    for a in stacking:
        for f in a.add:
            if f[0] == on:
                clear_candidates |= {g[0] for g in a.delete if g[1:] == f[2:]}
        for f in a.delete:
            if f[0] == on:
                clear_candidates |= {g[0] for g in a.add if g[1:] == f[2:]}
    clear_candidates &= unary - {holding}
    clear = _only(
        clear_candidates,
        f"no one-argument 'clear' predicate: none is deleted for ?y where ({on} ?x ?y) is "
        f"added or added for ?y where ({on} ?x ?y) is deleted (in "
        f"{', '.join(a.name for a in stacking)})",
        "cannot tell which of {} means 'clear'",
    )

    def about_held(a: ActionSchema, facts, held_facts) -> set[str]:
        held_args = {f[1:] for f in held_facts if f[0] == holding}
        return {f[0] for f in facts if len(f) == 2 and f[1:] in held_args}

    # added for ?x by an action that releases ?x, deleted for ?x by one that grasps ?x
    put = set().union(*(about_held(a, a.add, a.delete) for a in actions))
    taken = set().union(*(about_held(a, a.delete, a.add) for a in actions))
    table_candidates = (put & taken) - {holding, clear}
    on_table = _only(
        table_candidates,
        f"no one-argument 'on the table' predicate: none besides '{clear}' is added for ?x "
        f"by an action that deletes ({holding} ?x) and deleted by one that adds it",
        "cannot tell which of {} means 'on the table'",
    )
    roles = {on, on_table, clear, holding, hand_empty}
    for p, (a, _) in fluents.items():
        if p not in roles:
            _fail(
                f"action '{a}' changes '{p}', which means none of on, on the table, clear, "
                f"holding, hand empty (here '{on}', '{on_table}', '{clear}', '{holding}', "
                f"'{hand_empty}'): the robot cannot do that"
            )
    return Vocabulary(on, on_table, clear, holding, hand_empty)


def _read_action(a: ActionSchema, v: Vocabulary) -> ActionRole:
    def where(fs, p):
        return [f for f in fs if f[0] == p]

    params = [p for p, _ in a.params]

    def index(var: str, fact: Fact) -> int:
        if var not in params:
            _fail(f"action '{a.name}': {fact_str(fact)} names '{var}', not a parameter")
        return params.index(var)

    picked, released = where(a.add, v.holding), where(a.delete, v.holding)
    if len(picked) + len(released) != 1:
        _fail(
            f"action '{a.name}' adds {len(picked)} and deletes {len(released)} "
            f"({v.holding} ...) facts; a pick adds one, a place deletes one"
        )
    if picked:
        x = picked[0][1]
        block = index(x, picked[0])
        moved = [f for f in where(a.delete, v.on) if f[1] == x]
        y = moved[0][2] if moved else None
        pre = {(v.clear, x), (v.hand_empty,)}
        pre |= {(v.on_table, x)} if y is None else {(v.on, x, y)}
        delete = set(pre)
        add = {(v.holding, x)} | (set() if y is None else {(v.clear, y)})
        role = ActionRole(PICK, block, None if y is None else index(y, moved[0]))
    else:
        x = released[0][1]
        block = index(x, released[0])
        moved = [f for f in where(a.add, v.on) if f[1] == x]
        y = moved[0][2] if moved else None
        pre = {(v.holding, x)} | (set() if y is None else {(v.clear, y)})
        delete = set(pre)
        add = {(v.clear, x), (v.hand_empty,)}
        add |= {(v.on_table, x)} if y is None else {(v.on, x, y)}
        role = ActionRole(PLACE, block, None if y is None else index(y, moved[0]))
    if y == x:
        _fail(f"action '{a.name}': {fact_str(moved[0])} puts a block on itself")
    what = f"action '{a.name}' ({role.describe()}, {x} held)"
    wrong = []
    wrong += [f"lacks the precondition {fact_str(f)}" for f in sorted(pre - set(a.pre))]
    wrong += [f"does not add {fact_str(f)}" for f in sorted(add - set(a.add))]
    wrong += [f"does not delete {fact_str(f)}" for f in sorted(delete - set(a.delete))]
    wrong += [f"also adds {fact_str(f)}" for f in sorted(set(a.add) - add)]
    wrong += [f"also deletes {fact_str(f)}" for f in sorted(set(a.delete) - delete)]
    used = {x} | ({y} if y is not None else set())
    wrong += [
        f"has parameter {p}, neither the block nor its support" for p in params if p not in used
    ]
    if wrong:
        _fail(f"{what} {'; '.join(wrong)}")
    return role


_CACHE: weakref.WeakKeyDictionary[Domain, BlocksworldRoles] = weakref.WeakKeyDictionary()


def blocksworld_roles(domain: Domain) -> BlocksworldRoles:
    """Read ``domain`` as a Blocksworld domain; :class:`InputError` (exit 2) if it is not one.

    The message is one line: ``FILE: not a Blocksworld domain the robot can
    execute: <the action or predicate and what is missing>``.
    """
    cached = _CACHE.get(domain)
    if cached is not None:
        return cached
    try:
        vocabulary = _read_vocabulary(domain)
        actions = {a.name: _read_action(a, vocabulary) for a in domain.actions.values()}
    except _NotBlocksworld as e:
        raise InputError(
            f"{domain.path}: not a Blocksworld domain the robot can execute: {e}"
        ) from None
    block_types = sorted(
        {
            domain.actions[name].params[i][1]
            for name, r in actions.items()
            for i in (r.block, r.support)
            if i is not None
        }
    )
    roles = BlocksworldRoles(domain.name, vocabulary, actions, tuple(block_types))
    _CACHE[domain] = roles
    return roles


def is_blocksworld(domain: Domain) -> bool:
    """True when :func:`blocksworld_roles` can read ``domain``."""
    try:
        blocksworld_roles(domain)
    except InputError:
        return False
    return True


@dataclass(frozen=True)
class BlocksworldView:
    """A problem in canonical names: what the world lays out and checks against."""

    roles: BlocksworldRoles
    blocks: tuple[str, ...]
    init: frozenset[Fact]
    goal: frozenset[Fact]


def blocksworld_view(problem: Problem) -> BlocksworldView:
    """``problem``'s blocks, initial state and goal in canonical names (see :data:`CANONICAL`).

    Raises :class:`InputError` when its domain is not a Blocksworld domain.
    """
    roles = blocksworld_roles(problem.domain)
    return BlocksworldView(
        roles,
        tuple(roles.blocks(problem)),
        roles.to_canonical(problem.init),
        roles.to_canonical(problem.goal),
    )
