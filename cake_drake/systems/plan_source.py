"""``PlanSource``: the symbolic layer's voice in the Diagram."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from cake_drake.symbolic import GroundAction

#: The same ground action ended without its effects this many times in a row: the run
#: stops, naming it (the layer below cannot do it here). The learned skills and the
#: execution monitor both keep it.
MAX_TRIES = 3


@dataclass(frozen=True)
class ActionCommand:
    """The action to execute now: its index in the plan, or ``action=None`` when done."""

    index: int
    action: GroundAction | None

    def __deepcopy__(self, memo):  # immutable: Drake's value copies may share it
        return self


@dataclass(frozen=True)
class Refusal:
    """The geometric layer's answer that an action cannot be done where the world is now
    (``index`` -1: none). An action source with an ``infeasible`` input port hears it and
    may give another action at the same index; without one, the run stops."""

    index: int = -1
    action: GroundAction | None = None
    reason: str = ""

    def __deepcopy__(self, memo):
        return self


class PlanSource(LeafSystem):
    """Emits the current ground action of a plan and advances as actions are reported done.

    .. pydrake_system::

        name: PlanSource
        input_ports:
        - actions_done
        output_ports:
        - action

    ``actions_done`` is the number of actions the executor has finished; ``action`` is an
    :class:`ActionCommand` for the next one (``action=None`` once the plan is through).
    The plan is a parameter of the system, so another source of actions (a learned
    policy, a replanner) can take its place behind the same two ports.
    """

    def __init__(self, actions: Sequence[GroundAction]) -> None:
        super().__init__()
        self._actions = tuple(actions)
        self._done_port = self.DeclareVectorInputPort("actions_done", 1)
        self.DeclareAbstractOutputPort(
            "action",
            lambda: AbstractValue.Make(ActionCommand(0, None)),
            self._calc_action,
            prerequisites_of_calc={self._done_port.ticket()},
        )

    @property
    def actions(self) -> tuple[GroundAction, ...]:
        return self._actions

    def _calc_action(self, context, output) -> None:
        done = int(round(self._done_port.Eval(context)[0]))
        action = self._actions[done] if done < len(self._actions) else None
        output.set_value(ActionCommand(done, action))
