"""The project's own LeafSystems, one per file: :class:`PlanSource` and :class:`WaypointIk`.

:data:`ACTION_SOURCES` is the registry of action sources a scenario can name
(``reference: {action_source: plan}``); :func:`make_action_source` builds one, or a
user's ``module:attribute`` factory, and checks its ports.
"""

from __future__ import annotations

from collections.abc import Sequence

from pydrake.systems.framework import LeafSystem

from cake_drake.errors import InputError
from cake_drake.plugins import resolve
from cake_drake.symbolic import GroundAction, Problem
from cake_drake.systems.plan_source import ActionCommand, PlanSource

#: Action sources by name, each a factory ``(actions, problem, blocks) -> System``.
ACTION_SOURCES = {"plan": lambda actions, problem, blocks: PlanSource(actions)}


def make_action_source(
    spec: str, actions: Sequence[GroundAction], problem: Problem, blocks: Sequence[str]
) -> LeafSystem:
    """The action source ``spec`` names.

    A factory is called with the planned ``actions``, the ``problem`` (its goal, for a
    policy that decides for itself) and the ``blocks`` in the order of the plant's cube
    bodies. Protocol of what it returns: a System with a vector input ``actions_done``
    (size 1) and an abstract output ``action`` holding an :class:`ActionCommand` (index =
    actions done; ``action=None`` once it has nothing more to do). It may also have an
    abstract input ``body_poses`` (the plant's body poses), which is then connected.
    """
    factory = resolve(spec, ACTION_SOURCES, "action source")
    system = factory(tuple(actions), problem, tuple(blocks))
    if not hasattr(system, "HasInputPort"):
        raise InputError(
            f"action source {spec!r} returned a {type(system).__name__}, not a Drake System"
        )
    missing = [f"input port {n!r}" for n in ("actions_done",) if not system.HasInputPort(n)]
    missing += [f"output port {n!r}" for n in ("action",) if not system.HasOutputPort(n)]
    if missing:
        raise InputError(
            f"action source {spec!r} has no {' and no '.join(missing)} "
            "(the protocol: input actions_done, output action; optional input body_poses)"
        )
    return system


__all__ = ["ACTION_SOURCES", "ActionCommand", "PlanSource", "make_action_source"]
