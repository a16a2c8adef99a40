"""The project's own LeafSystems, one per file: :class:`PlanSource` (``plan_source``),
:class:`ExecutionMonitor` (``monitor``), :class:`WaypointIk` (``waypoint_ik``: the
geometric layer), ``LearnedSkills`` (``skills``: the geometric layer learned) and
``PolicySource`` (``policy_source``: a whole-task policy in the source's and the IK's
place). The perception layer's estimator lives in :mod:`cake_drake.perception`.

:data:`ACTION_SOURCES` is the registry of action sources a scenario can name
(``reference: {action_source: monitor}``); :func:`make_action_source` builds one, or a
user's ``module:attribute`` factory, and checks its ports.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from pydrake.systems.framework import LeafSystem

from cake_drake.errors import InputError
from cake_drake.plugins import resolve
from cake_drake.symbolic import GroundAction, Problem
from cake_drake.systems.monitor import ExecutionMonitor
from cake_drake.systems.plan_source import ActionCommand, PlanSource
from cake_drake.systems.waypoint_ik import WorldIndices


@dataclass(frozen=True)
class SourceContext:
    """What an action-source factory is given."""

    actions: tuple[GroundAction, ...]  # the planner's plan
    problem: Problem  # its goal, its domain (read by structure: symbolic.roles)
    world: WorldIndices  # where the cubes and the hand are in the plant's body_poses
    planner: Callable  # the run's planner, (problem, time_limit) -> Plan, for replanning
    period: float  # the simulation step (s), for a periodic update
    max_replans: int = 5
    re_place: bool = False  # set a loose goal stack's cube down again (the monitor)


#: Action sources by name, each a factory ``(SourceContext) -> System``: ``monitor`` (the
#: default: checks every action against the measured world and replans) and ``plan``
#: (open loop: the plan's actions one after another).
ACTION_SOURCES: dict[str, Callable[[SourceContext], LeafSystem]] = {
    "plan": lambda c: PlanSource(c.actions),
    "monitor": lambda c: ExecutionMonitor(
        c.actions,
        c.problem,
        dict(c.world.cube_bodies),
        c.world.hand_body,
        c.world.X_hand_grasp,
        c.planner,
        c.period,
        c.max_replans,
        c.re_place,
    ),
}


def make_action_source(spec: str, context: SourceContext) -> LeafSystem:
    """The action source ``spec`` names, built from ``context``.

    Protocol of what a factory returns: a System with a vector input ``actions_done``
    (size 1) and an abstract output ``action`` holding an :class:`ActionCommand` (index =
    actions done; ``action=None`` with that index once it has nothing more to do). It may
    also have the abstract input ``body_poses`` (the world's body poses: the plant's, or
    the perception layer's estimate), ``cube_estimates`` (the perception layer's, when it
    has one) and the vector input ``hand_state`` (the fingers' positions and velocities),
    which are then connected, and the methods ``error(context)`` (why it stopped, or None) and
    ``executed(context)`` (the actions it gave, in order).
    """
    factory = resolve(spec, ACTION_SOURCES, "action source")
    system = factory(context)
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


__all__ = [
    "ACTION_SOURCES",
    "ActionCommand",
    "ExecutionMonitor",
    "PlanSource",
    "SourceContext",
    "make_action_source",
]
