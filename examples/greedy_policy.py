"""An action-source plug-in: a policy that looks at the world, instead of a plan.

:class:`GreedyTowerPolicy` ignores the planner's plan. Whenever the arm is idle it
reads the cubes' measured poses, turns them into Blocksworld facts and picks the next
action by the classic rule for towers: move a clear block straight to its goal place
when that place is ready (the table, or a clear block that is itself where it belongs);
otherwise put some misplaced clear block on the table. A learned policy would sit
behind the same ports: ``actions_done`` and ``body_poses`` in, ``action`` out.

Use it: ``reference: {action_source: examples.greedy_policy:make}``.
"""

from collections.abc import Sequence

from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem

from cake_drake.symbolic import GroundAction, Problem
from cake_drake.systems import ActionCommand
from cake_drake.world.facts import read_facts

TABLE = "table"


def goal_support(goal) -> dict[str, str]:
    """What each block should stand on in the goal (blocks the goal leaves out: the table)."""
    support = {f[1]: f[2] for f in goal if f[0] == "on"}
    support.update({f[1]: TABLE for f in goal if f[0] == "on-table"})
    return support


def next_action(facts, held: str | None, goal, blocks: Sequence[str]) -> GroundAction | None:
    """The policy: one action from the measured facts, or None when the goal holds."""
    on = {f[1]: f[2] for f in facts if f[0] == "on"}
    on.update({f[1]: TABLE for f in facts if f[0] == "on-table"})
    clear = {f[1] for f in facts if f[0] == "clear"}
    want = goal_support(goal)

    def in_place(b: str) -> bool:
        target = want.get(b, TABLE)
        return on.get(b) == target and (target == TABLE or in_place(target))

    def ready(b: str) -> bool:
        target = want.get(b, TABLE)
        return target == TABLE or (target in clear and in_place(target))

    if held is not None:
        target = want.get(held, TABLE)
        if target != TABLE and ready(held):
            return GroundAction("stack", (held, target))
        return GroundAction("put-down", (held,))
    if all(in_place(b) for b in blocks if b in want):
        return None
    movable = [b for b in sorted(clear) if not in_place(b)]
    for b in movable:  # straight to its goal place
        if ready(b) and want.get(b, TABLE) != TABLE:
            return _pick(b, on)
    for b in movable:  # out of the way, onto the table
        if on.get(b) != TABLE:
            return _pick(b, on)
    return None


def _pick(block: str, on: dict[str, str]) -> GroundAction:
    below = on[block]
    if below == TABLE:
        return GroundAction("pick-up", (block,))
    return GroundAction("unstack", (block, below))


class GreedyTowerPolicy(LeafSystem):
    """Emits the policy's next action each time the previous one is done.

    .. pydrake_system::

        name: GreedyTowerPolicy
        input_ports:
        - actions_done
        - body_poses
        output_ports:
        - action
    """

    def __init__(self, problem: Problem, cube_bodies: dict[str, int]) -> None:
        super().__init__()
        self._goal = problem.goal
        self._bodies = dict(cube_bodies)
        self._done_port = self.DeclareVectorInputPort("actions_done", 1)
        self._poses_port = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()])
        )
        self.DeclareAbstractOutputPort(
            "action", lambda: AbstractValue.Make(ActionCommand(0, None)), self._calc
        )

    def _calc(self, context, output) -> None:
        done = int(round(self._done_port.Eval(context)[0]))
        poses = self._poses_port.Eval(context)
        cubes = {name: poses[i] for name, i in self._bodies.items()}
        reading = read_facts(cubes)
        resting = {f[1] for f in reading.facts if f[0] in ("on", "on-table")}
        lifted = [b for b in cubes if b not in resting]  # in the hand, off any support
        held = lifted[0] if len(lifted) == 1 else None
        action = next_action(reading.facts, held, self._goal, sorted(cubes))
        output.set_value(ActionCommand(done, action))


def make(context) -> GreedyTowerPolicy:
    """The factory a scenario names (a :class:`cake_drake.systems.SourceContext`): the
    planner's actions are not used, the goal and the cubes' places in the plant are."""
    return GreedyTowerPolicy(context.problem, dict(context.world.cube_bodies))
