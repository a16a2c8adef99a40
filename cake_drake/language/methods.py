"""HTN-style methods: how one skill phrase becomes actions, depending on the state.

A STRIPS action has one meaning. A skill phrase of a language plan does not:
SayCan writes "go to the trash can, put down the redbull" to throw a can away, and
"put down the jalapeno chips" at the user to hand them over. The words are the
same; what they stand for depends on where the robot is. A hierarchical (HTN)
planner states this with *methods*: a task, a precondition on the state, and the
subtasks it decomposes into. This module is that, in small:

- :class:`Method`: a name, a precondition (fact patterns over the state, with the
  phrase's noun slots ``x``/``y`` and method variables ``?c``, ``?l``), the ordered
  actions it stands for, whether it is the *literal* reading of the words, and why
  it applies, in words.
- :func:`method_bindings`: the ways a method's precondition holds in a state.

A skill's methods are tried in order; the first whose precondition holds is
used (the literal one, last, has none). Every step's result names the method
that fired and why, so the decomposition is visible, not buried in the lexicon.
"""

from __future__ import annotations

from dataclasses import dataclass

from cake_drake.symbolic import Fact


@dataclass(frozen=True)
class MethodStep:
    """One action of a method: a schema name and its parameters filled from slots,
    method variables or constants.

    ``args`` maps a schema parameter (``?i``) to a slot (``x``/``y``), a method
    variable (``?c``) bound by the method's precondition, or an object name
    (``trash-can``). Parameters left out are bound from the state.
    """

    schema: str
    args: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True)
class Method:
    """A state-dependent decomposition of a skill phrase into actions (an HTN method)."""

    name: str
    steps: tuple[MethodStep, ...]
    pre: tuple[tuple[str, ...], ...] = ()  # fact patterns: slots, ?variables, constants
    literal: bool = False  # the plain reading of the words (one action, no condition)
    why: str = ""  # when it applies, in words; {x}, {y} and {?var} are filled in

    def describe(self) -> str:
        """``put-in ?c (when (at-location robot ?l) (container-at ?c ?l) (is-open ?c))``."""
        acts = " + ".join(s.schema for s in self.steps)
        if not self.pre:
            return f"{acts} (always)"
        return f"{acts} when " + " ".join("(" + " ".join(p) + ")" for p in self.pre)


def _is_var(term: str) -> bool:
    return term.startswith("?")


def method_bindings(
    method: Method, state: frozenset[Fact], slots: dict[str, str]
) -> list[dict[str, str]]:
    """Every binding of the method's variables under which all its ``pre`` facts hold.

    A plain conjunctive query over the state: patterns are matched left to right,
    each extending the bindings found so far. Slots (``x``, ``y``) are fixed by the
    phrase; a method without ``pre`` has exactly one (empty) binding.
    """
    by_pred: dict[str, list[Fact]] = {}
    for f in state:
        by_pred.setdefault(f[0], []).append(f)
    bindings: list[dict[str, str]] = [{}]
    for pattern in method.pre:
        pred, terms = pattern[0], pattern[1:]
        extended: list[dict[str, str]] = []
        for b in bindings:
            for fact in by_pred.get(pred, ()):
                if len(fact) != len(pattern):
                    continue
                nb = dict(b)
                for term, value in zip(terms, fact[1:], strict=True):
                    if _is_var(term):
                        if nb.setdefault(term, value) != value:
                            break
                    elif slots.get(term, term) != value:
                        break
                else:
                    extended.append(nb)
        bindings = extended
        if not bindings:
            break
    unique = {tuple(sorted(b.items())): b for b in bindings}
    return [unique[k] for k in sorted(unique)]


def explain(method: Method, slots: dict[str, str], binding: dict[str, str]) -> str:
    """The method's ``why`` with its slots and variables filled in."""
    values = {**slots, **{k[1:]: v for k, v in binding.items()}}
    try:
        return method.why.format(**values)
    except (KeyError, IndexError):
        return method.why
