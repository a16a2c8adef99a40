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
from cake_drake.symbolic import GroundAction
from cake_drake.systems.plan_source import ActionCommand, PlanSource

#: Action sources by name, each a factory ``(actions) -> LeafSystem``.
ACTION_SOURCES = {"plan": PlanSource}


def make_action_source(spec: str, actions: Sequence[GroundAction]) -> LeafSystem:
    """The action source ``spec`` names, for the planned ``actions``.

    Protocol: a System with a vector input ``actions_done`` (size 1) and an abstract output
    ``action`` holding an :class:`ActionCommand`; it may also have an abstract input
    ``body_poses`` (the plant's body poses), which is then connected.
    """
    factory = resolve(spec, ACTION_SOURCES, "action source")
    system = factory(tuple(actions))
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
