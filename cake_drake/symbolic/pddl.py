"""PDDL domains and problems (STRIPS with optional typing), checked with positions.

A :class:`Domain` and a :class:`Problem` are plain data: facts are tuples of
lower-case strings, ``("on", "a", "b")`` or ``("arm-empty",)``. Parsing checks
everything pyperplan would silently accept or reject without a position:
undefined predicates, objects and types (in ``:init`` too), arities, argument
types, a problem written for another domain, unsupported PDDL features. Each
error is one line, ``file:line:col: what is wrong (what would be valid)``.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

from cake_drake.errors import PddlError
from cake_drake.symbolic.sexpr import Atom, Node, SList, parse_sexprs, read_text, where

#: A ground or schematic fact: predicate name then arguments (``?x`` for variables).
Fact = tuple[str, ...]

#: PDDL requirements this layer understands.
SUPPORTED_REQUIREMENTS = (":strips", ":typing")

_UNSUPPORTED_CONNECTIVES = {
    "or": "disjunction (or ...)",
    "imply": "implication (imply ...)",
    "exists": "existential quantification (exists ...)",
    "forall": "universal quantification (forall ...)",
    "when": "conditional effects (when ...)",
    "=": "equality (= ...)",
    "increase": "numeric effects (increase ...)",
    "decrease": "numeric effects (decrease ...)",
}


def fact_str(fact: Fact) -> str:
    """``("on", "a", "b")`` -> ``"(on a b)"``."""
    return "(" + " ".join(fact) + ")"


def facts_str(facts: Iterable[Fact]) -> str:
    """Sorted facts, space separated: ``(clear a) (on a b)``."""
    return " ".join(fact_str(f) for f in sorted(facts))


@dataclass(frozen=True)
class GroundAction:
    """One step of a plan: an action schema name and its object arguments."""

    name: str
    args: tuple[str, ...] = ()

    def __str__(self) -> str:
        return "(" + " ".join((self.name, *self.args)) + ")"


@dataclass(frozen=True)
class Predicate:
    """A predicate declaration: name and ``(variable, type)`` parameters."""

    name: str
    params: tuple[tuple[str, str], ...]

    @property
    def arity(self) -> int:
        return len(self.params)

    def signature(self) -> str:
        return "(" + " ".join([self.name, *(v for v, _ in self.params)]) + ")"


@dataclass(frozen=True)
class ActionSchema:
    """A STRIPS action schema; facts may contain parameters (``?x``) and constants."""

    name: str
    params: tuple[tuple[str, str], ...]
    pre: tuple[Fact, ...]
    add: tuple[Fact, ...]
    delete: tuple[Fact, ...]

    @property
    def arity(self) -> int:
        return len(self.params)

    def signature(self) -> str:
        return "(" + " ".join([self.name, *(v for v, _ in self.params)]) + ")"


@dataclass(frozen=True, eq=False)
class Domain:
    """A parsed PDDL domain."""

    name: str
    requirements: tuple[str, ...]
    types: dict[str, str]  # type -> parent type ("object" is the root)
    constants: dict[str, str]  # constant -> type
    predicates: dict[str, Predicate]
    actions: dict[str, ActionSchema]
    path: str = "<string>"
    text: str = field(default="", repr=False)

    def is_subtype(self, t: str, ancestor: str) -> bool:
        """True when type ``t`` is ``ancestor`` or derives from it."""
        seen = set()
        while t not in seen:
            if t == ancestor:
                return True
            seen.add(t)
            t = self.types.get(t, "object")
        return ancestor == "object"

    @property
    def static_predicates(self) -> frozenset[str]:
        """Predicates no action adds or deletes (their truth never changes)."""
        changed = {f[0] for a in self.actions.values() for f in (*a.add, *a.delete)}
        return frozenset(p for p in self.predicates if p not in changed)


@dataclass(frozen=True, eq=False)
class Problem:
    """A parsed PDDL problem together with its domain."""

    name: str
    domain_name: str
    domain: Domain
    objects: tuple[str, ...]  # declared in :objects, in declaration order
    object_types: dict[str, str]  # every usable object (objects and constants) -> type
    init: frozenset[Fact]
    goal: frozenset[Fact]
    has_goal: bool = True
    domain_path: str = "<string>"
    problem_path: str = "<string>"
    text: str = field(default="", repr=False)

    def objects_of_type(self, t: str) -> list[str]:
        """Objects (and constants) of type ``t`` or a subtype, sorted by name."""
        return sorted(o for o, ot in self.object_types.items() if self.domain.is_subtype(ot, t))


# --------------------------------------------------------------------------- helpers


def _listing(names: Iterable[str], limit: int = 20) -> str:
    names = list(names)
    if not names:
        return "none"
    shown = ", ".join(names[:limit])
    return shown if len(names) <= limit else f"{shown}, ... ({len(names) - limit} more)"


def _suggest(word: str, choices: Iterable[str]) -> str:
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.75)
    return f"did you mean '{close[0]}'? " if close else ""


def _head(node: Node) -> str | None:
    if isinstance(node, SList) and node.items and isinstance(node.items[0], Atom):
        return node.items[0].text
    return None


def _show(node: Node, limit: int = 60) -> str:
    def render(n: Node) -> str:
        if isinstance(n, Atom):
            return n.text
        return "(" + " ".join(render(c) for c in n.items) + ")"

    s = render(node)
    return s if len(s) <= limit else s[: limit - 3] + "..."


class _Ctx:
    """Source name plus an error factory."""

    def __init__(self, source: str):
        self.source = source

    def err(self, node: Node | None, msg: str) -> PddlError:
        return PddlError(f"{where(self.source, node)}: {msg}")


def _root(nodes: list[Node], ctx: _Ctx, kind: str) -> SList:
    """Check the file is exactly one ``(define (KIND NAME) ...)`` and return it."""
    other = "problem" if kind == "domain" else "domain"
    if not nodes:
        raise ctx.err(
            None, f"contains no PDDL (only comments); expected (define ({kind} NAME) ...)"
        )
    root = nodes[0]
    if _head(root) != "define":
        raise ctx.err(root, f"expected (define ({kind} NAME) ...), got {_show(root, 40)}")
    assert isinstance(root, SList)
    if len(root.items) < 2 or _head(root.items[1]) not in (kind, other):
        raise ctx.err(root, f"expected ({kind} NAME) after 'define'")
    header = root.items[1]
    assert isinstance(header, SList)
    if _head(header) == other:
        raise ctx.err(
            header,
            f"this is a {other} file, expected a {kind} file "
            "(give the domain first, then the problem)",
        )
    if len(header.items) != 2 or not isinstance(header.items[1], Atom):
        raise ctx.err(header, f"expected ({kind} NAME), got {_show(header)}")
    if len(nodes) > 1:
        raise ctx.err(nodes[1], "unexpected text after the (define ...) form")
    return root


def _sections(root: SList, ctx: _Ctx, allowed: tuple[str, ...]) -> list[tuple[str, SList]]:
    out = []
    seen: dict[str, SList] = {}
    for node in root.items[2:]:
        head = _head(node)
        if head is None or not head.startswith(":"):
            raise ctx.err(node, f"expected a section such as ({allowed[0]} ...), got {_show(node)}")
        assert isinstance(node, SList)
        if head not in allowed:
            raise ctx.err(
                node.items[0],
                f"section {head} is not supported here (supported: {', '.join(allowed)})",
            )
        if head in seen and head != ":action":
            raise ctx.err(node, f"second {head} section (the first is at line {seen[head].line})")
        seen[head] = node
        out.append((head, node))
    return out


def _check_requirements(node: SList, ctx: _Ctx) -> tuple[str, ...]:
    reqs = []
    for item in node.items[1:]:
        if not isinstance(item, Atom) or item.text not in SUPPORTED_REQUIREMENTS:
            raise ctx.err(
                item,
                f"requirement {_show(item)} is not supported "
                f"(supported: {', '.join(SUPPORTED_REQUIREMENTS)}; STRIPS with types)",
            )
        reqs.append(item.text)
    return tuple(reqs)


def _typed_list(items: Iterable[Node], ctx: _Ctx, variables: bool) -> list[tuple[Atom, str, Node]]:
    """Parse ``a b - t c`` into ``[(a, t), (b, t), (c, object)]`` (with the type's node)."""
    out: list[tuple[Atom, str, Node]] = []
    pending: list[Atom] = []
    items = list(items)
    i = 0
    while i < len(items):
        item = items[i]
        if isinstance(item, Atom) and item.text == "-":
            if not pending or i + 1 >= len(items):
                raise ctx.err(item, "'-' must stand between names and their type: NAME ... - TYPE")
            t = items[i + 1]
            if not isinstance(t, Atom):
                raise ctx.err(t, f"expected a type name after '-', got {_show(t)} (no 'either')")
            out.extend((p, t.text, t) for p in pending)
            pending = []
            i += 2
            continue
        if not isinstance(item, Atom):
            raise ctx.err(item, f"expected a name, got {_show(item)}")
        if variables and not item.text.startswith("?"):
            raise ctx.err(item, f"expected a variable such as ?x, got '{item.text}'")
        if not variables and (item.text.startswith("?") or item.text.startswith(":")):
            raise ctx.err(item, f"expected an object name, got '{item.text}'")
        pending.append(item)
        i += 1
    out.extend((p, "object", p) for p in pending)
    return out


def _check_type(t: str, node: Node, types: dict[str, str], ctx: _Ctx) -> None:
    if t != "object" and t not in types:
        declared = ["object", *sorted(types)]
        raise ctx.err(
            node,
            f"type '{t}' is not declared in :types ({_suggest(t, declared)}declared: "
            f"{_listing(declared)})",
        )


# --------------------------------------------------------------------------- domain


def parse_domain(text: str, source: str = "<string>") -> Domain:
    """Parse and check a PDDL domain given as text."""
    ctx = _Ctx(source)
    root = _root(parse_sexprs(text, source), ctx, "domain")
    name = root.items[1].items[1].text  # type: ignore[union-attr]
    sections = _sections(
        root, ctx, (":requirements", ":types", ":constants", ":predicates", ":action")
    )
    by_kind: dict[str, list[SList]] = {}
    for kind, node in sections:
        by_kind.setdefault(kind, []).append(node)

    requirements: tuple[str, ...] = ()
    for node in by_kind.get(":requirements", []):
        requirements = _check_requirements(node, ctx)
    typing = ":typing" in requirements

    types: dict[str, str] = {}
    type_nodes: dict[str, Node] = {}
    for node in by_kind.get(":types", []):
        if not typing:
            raise ctx.err(node, "(:types ...) needs (:requirements :typing)")
        for atom, parent, pnode in _typed_list(node.items[1:], ctx, variables=False):
            if atom.text == "object":
                continue
            if atom.text in types:
                raise ctx.err(atom, f"type '{atom.text}' is declared twice")
            types[atom.text] = parent
            type_nodes[atom.text] = pnode
    for t, parent in types.items():
        _check_type(parent, type_nodes[t], types, ctx)
        seen = {t}
        p = parent
        while p != "object":
            if p in seen:
                raise ctx.err(type_nodes[t], f"type '{t}' is its own ancestor (cycle in :types)")
            seen.add(p)
            p = types[p]

    def check_declared_type(t: str, node: Node) -> None:
        if not typing and t != "object":
            raise ctx.err(node, f"type '{t}' used but the domain lacks (:requirements :typing)")
        _check_type(t, node, types, ctx)

    constants: dict[str, str] = {}
    for node in by_kind.get(":constants", []):
        for atom, t, tnode in _typed_list(node.items[1:], ctx, variables=False):
            check_declared_type(t, tnode)
            if atom.text in constants:
                raise ctx.err(atom, f"constant '{atom.text}' is declared twice")
            constants[atom.text] = t

    predicates: dict[str, Predicate] = {}
    for node in by_kind.get(":predicates", []):
        for decl in node.items[1:]:
            head = _head(decl)
            if head is None:
                raise ctx.err(
                    decl, f"expected a predicate declaration (NAME ?x ...), got {_show(decl)}"
                )
            assert isinstance(decl, SList)
            if head in predicates:
                raise ctx.err(decl, f"predicate '{head}' is declared twice")
            params = []
            for atom, t, tnode in _typed_list(decl.items[1:], ctx, variables=True):
                check_declared_type(t, tnode)
                params.append((atom.text, t))
            predicates[head] = Predicate(head, tuple(params))

    domain = Domain(name, requirements, types, constants, predicates, {}, source, text)
    for node in by_kind.get(":action", []):
        schema = _parse_action(node, domain, ctx, check_declared_type)
        if schema.name in domain.actions:
            raise ctx.err(node, f"action '{schema.name}' is defined twice")
        domain.actions[schema.name] = schema
    if not domain.actions:
        raise ctx.err(root, f"domain '{name}' defines no (:action ...)")
    return domain


def _parse_action(node: SList, domain: Domain, ctx: _Ctx, check_type) -> ActionSchema:
    if len(node.items) < 2 or not isinstance(node.items[1], Atom):
        raise ctx.err(
            node, "expected (:action NAME :parameters (...) :precondition ... :effect ...)"
        )
    name = node.items[1].text
    parts: dict[str, Node] = {}
    rest = list(node.items[2:])
    for i in range(0, len(rest), 2):
        key = rest[i]
        if not isinstance(key, Atom) or key.text not in (":parameters", ":precondition", ":effect"):
            raise ctx.err(
                key,
                f"in action '{name}': expected :parameters, :precondition or :effect, "
                f"got {_show(key)}",
            )
        if i + 1 >= len(rest):
            raise ctx.err(key, f"in action '{name}': {key.text} has no value")
        if key.text in parts:
            raise ctx.err(key, f"in action '{name}': {key.text} given twice")
        parts[key.text] = rest[i + 1]

    params: list[tuple[str, str]] = []
    pnode = parts.get(":parameters")
    if pnode is not None:
        if not isinstance(pnode, SList):
            raise ctx.err(pnode, f"in action '{name}': :parameters must be a list (?x ?y ...)")
        for atom, t, tnode in _typed_list(pnode.items, ctx, variables=True):
            check_type(t, tnode)
            if atom.text in dict(params):
                raise ctx.err(atom, f"in action '{name}': parameter {atom.text} is declared twice")
            params.append((atom.text, t))
    variables = dict(params)

    def atoms(formula: Node | None, what: str, allow_not: bool) -> tuple[list[Fact], list[Fact]]:
        pos: list[Fact] = []
        neg: list[Fact] = []
        if formula is not None:
            _conjunction(formula, ctx, allow_not, pos, neg, what=f"{what} of action '{name}'")
        for fact, fnode in [*pos, *neg]:
            _check_atom(
                fact,
                fnode,
                domain,
                ctx,
                variables=variables,
                objects=domain.constants,
                object_word="constant",
            )
        return [f for f, _ in pos], [f for f, _ in neg]

    pre, _ = atoms(parts.get(":precondition"), "precondition", allow_not=False)
    add, delete = atoms(parts.get(":effect"), "effect", allow_not=True)
    return ActionSchema(name, tuple(params), tuple(pre), tuple(add), tuple(delete))


def _conjunction(
    node: Node, ctx: _Ctx, allow_not: bool, pos: list, neg: list, what: str, negated: bool = False
) -> None:
    """Collect the atoms of ``(and ...)``/atom/``(not atom)`` into pos/neg as (fact, node)."""
    if isinstance(node, Atom):
        raise ctx.err(
            node, f"in the {what}: expected an atom such as (on ?x ?y), got '{node.text}'"
        )
    if not node.items:
        return  # () is the empty conjunction
    head = node.items[0]
    if not isinstance(head, Atom):
        raise ctx.err(
            node, f"in the {what}: expected an atom such as (on ?x ?y), got {_show(node)}"
        )
    if head.text == "and" and not negated:
        for child in node.items[1:]:
            _conjunction(child, ctx, allow_not, pos, neg, what)
        return
    if head.text == "not" and not negated:
        if not allow_not:
            raise ctx.err(
                node,
                f"in the {what}: negative conditions (not ...) are not supported "
                "(STRIPS: positive preconditions and goals only)",
            )
        if len(node.items) != 2:
            raise ctx.err(node, f"in the {what}: (not ...) takes exactly one atom")
        _conjunction(node.items[1], ctx, allow_not, pos, neg, what, negated=True)
        return
    if head.text in _UNSUPPORTED_CONNECTIVES or head.text in ("and", "not"):
        feature = _UNSUPPORTED_CONNECTIVES.get(head.text, f"({head.text} ...) here")
        raise ctx.err(node, f"in the {what}: {feature} is not supported (STRIPS only)")
    args = []
    for a in node.items[1:]:
        if not isinstance(a, Atom):
            raise ctx.err(a, f"in the {what}: expected an object or variable, got {_show(a)}")
        args.append(a.text)
    (neg if negated else pos).append(((head.text, *args), node))


def _check_atom(
    fact: Fact,
    node: Node,
    domain: Domain,
    ctx: _Ctx,
    variables: dict[str, str] | None,
    objects: dict[str, str],
    object_word: str = "object",
) -> None:
    """Check predicate, arity, and that arguments are declared (and well typed if ground)."""
    pred = domain.predicates.get(fact[0])
    head_node = node.items[0] if isinstance(node, SList) else node
    if pred is None:
        raise ctx.err(
            head_node,
            f"predicate '{fact[0]}' is not defined in domain '{domain.name}' "
            f"({_suggest(fact[0], domain.predicates)}"
            f"defined: {_listing(sorted(domain.predicates))})",
        )
    args = fact[1:]
    if len(args) != pred.arity:
        raise ctx.err(
            node,
            f"predicate '{pred.name}' takes {pred.arity} argument{'s' * (pred.arity != 1)} "
            f"{pred.signature()}, got {len(args)}: {fact_str(fact)}",
        )
    for i, arg in enumerate(args):
        arg_node = node.items[i + 1] if isinstance(node, SList) else node
        if arg.startswith("?"):
            if variables is None:
                raise ctx.err(arg_node, f"variable {arg} in a ground fact; expected an object name")
            if arg not in variables:
                raise ctx.err(
                    arg_node,
                    f"variable {arg} is not a parameter (parameters: {_listing(variables)})",
                )
            continue
        if arg not in objects:
            raise ctx.err(
                arg_node,
                f"{object_word} '{arg}' is not declared ({_suggest(arg, objects)}declared: "
                f"{_listing(objects)})",
            )
        want = pred.params[i][1]
        if variables is None and not domain.is_subtype(objects[arg], want):
            raise ctx.err(
                arg_node,
                f"'{arg}' has type '{objects[arg]}' but argument {i + 1} of {pred.signature()} "
                f"needs type '{want}'",
            )


def load_domain(path: str | Path) -> Domain:
    """Read, parse and check a domain file."""
    return parse_domain(read_text(path, "PDDL domain file"), str(path))


# --------------------------------------------------------------------------- problem


def parse_problem(
    domain: Domain, text: str, source: str = "<string>", require_goal: bool = True
) -> Problem:
    """Parse and check a PDDL problem (given as text) against ``domain``."""
    ctx = _Ctx(source)
    root = _root(parse_sexprs(text, source), ctx, "problem")
    name = root.items[1].items[1].text  # type: ignore[union-attr]
    sections = dict(
        _sections(root, ctx, (":domain", ":requirements", ":objects", ":init", ":goal"))
    )
    dnode = sections.get(":domain")
    if dnode is None:
        raise ctx.err(root, f"problem '{name}' has no (:domain NAME) section")
    if len(dnode.items) != 2 or not isinstance(dnode.items[1], Atom):
        raise ctx.err(dnode, "expected (:domain NAME)")
    domain_name = dnode.items[1].text
    if domain_name != domain.name:
        raise ctx.err(
            dnode.items[1],
            f"problem '{name}' is for domain '{domain_name}' but {domain.path} defines "
            f"domain '{domain.name}'",
        )
    if ":requirements" in sections:
        _check_requirements(sections[":requirements"], ctx)

    typing = ":typing" in domain.requirements
    object_types = dict(domain.constants)
    objects: list[str] = []
    if ":objects" in sections:
        for atom, t, tnode in _typed_list(sections[":objects"].items[1:], ctx, variables=False):
            if t != "object" and not typing:
                raise ctx.err(tnode, f"type '{t}' used but domain '{domain.name}' is untyped")
            _check_type(t, tnode, domain.types, ctx)
            if atom.text in object_types:
                what = "a domain constant" if atom.text in domain.constants else "already declared"
                raise ctx.err(atom, f"object '{atom.text}' is {what}")
            object_types[atom.text] = t
            objects.append(atom.text)

    init: set[Fact] = set()
    inode = sections.get(":init")
    if inode is None:
        raise ctx.err(root, f"problem '{name}' has no (:init ...) section")
    for item in inode.items[1:]:
        if not isinstance(item, SList) or not item.items or _head(item) in ("and", "not", "="):
            raise ctx.err(
                item,
                f"in :init: expected a ground atom such as (on a b), got {_show(item)} "
                "(only positive facts; everything else is false)",
            )
        pos: list = []
        _conjunction(item, ctx, False, pos, [], what=":init")
        for fact, fnode in pos:
            _check_atom(fact, fnode, domain, ctx, variables=None, objects=object_types)
            init.add(fact)

    goal: set[Fact] = set()
    gnode = sections.get(":goal")
    if gnode is None:
        if require_goal:
            raise ctx.err(root, f"problem '{name}' has no (:goal ...) section")
    else:
        if len(gnode.items) != 2:
            raise ctx.err(
                gnode, "expected (:goal FORMULA) with exactly one formula, e.g. (and ...)"
            )
        pos = []
        _conjunction(gnode.items[1], ctx, False, pos, [], what=":goal")
        for fact, fnode in pos:
            _check_atom(fact, fnode, domain, ctx, variables=None, objects=object_types)
            goal.add(fact)

    return Problem(
        name=name,
        domain_name=domain_name,
        domain=domain,
        objects=tuple(objects),
        object_types=object_types,
        init=frozenset(init),
        goal=frozenset(goal),
        has_goal=gnode is not None,
        domain_path=domain.path,
        problem_path=source,
        text=text,
    )


def load_problem(
    domain_path: str | Path, problem_path: str | Path, require_goal: bool = True
) -> Problem:
    """Read, parse and check a domain file and a problem file for it."""
    domain = load_domain(domain_path)
    text = read_text(problem_path, "PDDL problem file")
    return parse_problem(domain, text, str(problem_path), require_goal=require_goal)
