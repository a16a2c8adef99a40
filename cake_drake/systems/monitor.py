"""``ExecutionMonitor``: the symbolic layer closing the loop on the measured world."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector, LeafSystem

from cake_drake.errors import CakeDrakeError
from cake_drake.perception.estimator import Estimates
from cake_drake.symbolic import GroundAction, Plan, Problem, fact_str, validate_plan
from cake_drake.symbolic.grounding import apply_action, ground_all
from cake_drake.symbolic.kernels import kernels, latest_kernel
from cake_drake.symbolic.roles import PICK, PLACE, blocksworld_roles, blocksworld_view
from cake_drake.systems.plan_source import MAX_TRIES, ActionCommand, Refusal
from cake_drake.world.facts import STACK_TOL, lost_cubes, read_facts, stack_offsets

#: m: a goal's stacked cube standing farther than this off the one below is set down
#: again: the verdict's own tolerance, so the loop mends what the verdict would fail.
LOOSE = STACK_TOL

#: How long (s) the monitor waits for a disturbed world to come to rest before it judges.
SETTLE_WAIT_S = 1.5


@dataclass(frozen=True)
class MonitorState:
    """Immutable: Drake's state copies share it."""

    plan: tuple[GroundAction, ...]
    pos: int = 0  # index into ``plan`` of the action to emit next
    seen: int = -1  # actions done when the world was last checked (-1: not yet)
    replans: int = 0
    checks: int = 0
    emitted: tuple[GroundAction, ...] = ()  # the action given at each global index
    events: tuple[dict, ...] = ()
    error: str | None = None
    waiting_since: float | None = None  # the world was not at rest: waiting since then
    #: (measured facts, action) pairs the geometric layer refused: not planned again there.
    forbidden: frozenset = frozenset()
    #: The plan's first actions are a re-place, done in order (not skipped where a later
    #: kernel holds: the cube goes to the table before it is stacked again).
    forced: int = 0
    #: The action last repeated because it left the world without its effects, and how
    #: many times in a row (MAX_TRIES stops the run).
    failing: GroundAction | None = None
    tries: int = 0
    #: Each stack that left its cube on its support: (the action, the cube's horizontal
    #: offset from the one below in m), measured when the action ended.
    places: tuple[tuple[str, float], ...] = ()

    def __deepcopy__(self, memo):
        return self


def _meets_forbidden(problem: Problem, actions, forbidden) -> bool:
    """Whether the plan takes an action in a state where it is forbidden."""
    if not forbidden:
        return False
    state = problem.init
    for a in actions:
        if (state, a) in forbidden:
            return True
        state = apply_action(problem, state, a)
    return False


class ExecutionMonitor(LeafSystem):
    """Checks the measured world after every action against what the rest of the plan
    needs (its triangle-table kernels), skips ahead or repeats where a kernel holds, and
    replans from the measured facts where none does. With ``re_place``, a goal's stacked
    cube that stands farther than :data:`LOOSE` off the one below (the verdict would fail
    it, yet the facts hold) is taken off first: it and the cubes above it to the table,
    then the planner's plan from there (an event of kind ``re-place``, counted as a
    replan).

    .. pydrake_system::

        name: ExecutionMonitor
        input_ports:
        - actions_done
        - body_poses
        - hand_state
        - infeasible
        - cube_estimates
        output_ports:
        - action

    ``hand_state`` is the hand's state (finger positions and velocities): with the grasp
    frame's pose it tells a cube really in the hand from one that slipped. ``action`` is
    an :class:`ActionCommand` for the next action; while a finished action is being
    checked it carries an index behind ``actions_done``, so nothing starts and the run is
    not taken as finished. ``infeasible`` (optional) is the geometric layer's
    :class:`Refusal` of an action it cannot do where the world is now: that action is
    forbidden in that state and the rest replanned around it (TAMP at its simplest: the
    plan hears of geometry before the arm moves). ``cube_estimates`` (optional) is the
    perception layer's: a cube that no camera sees and none carries is unknown, and the
    run stops naming it ("cube c not seen by any camera since 4.2 s") rather than plan
    from a guess. At most ``max_replans`` replans; an
    unrecoverable world (a cube off the table, the budget spent, no plan from the measured
    facts) stops the run with :meth:`error` naming the fact.
    """

    def __init__(
        self,
        actions: Sequence[GroundAction],
        problem: Problem,
        cube_bodies: dict[str, int],
        hand_body: int,
        X_hand_grasp: RigidTransform,
        planner: Callable,
        period: float,
        max_replans: int = 5,
        re_place: bool = False,
    ) -> None:
        super().__init__()
        self._problem = problem
        self._roles = blocksworld_roles(problem.domain)
        self._goal = blocksworld_view(problem).goal  # canonical
        vocabulary = set(self._roles.vocabulary.as_dict().values())
        self._static = frozenset(f for f in problem.init if f[0] not in vocabulary)
        self._bodies = dict(cube_bodies)
        self._hand = hand_body
        self._X_HG = X_hand_grasp
        self._planner = planner
        self._max_replans = max_replans
        self._re_place_loose = re_place
        self._done_port = self.DeclareVectorInputPort("actions_done", 1)
        self._poses_port = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()])
        )
        self._hand_port = self.DeclareVectorInputPort("hand_state", BasicVector(4))
        self._refusal_port = self.DeclareAbstractInputPort(
            "infeasible", AbstractValue.Make(Refusal())
        )
        self._estimates_port = self.DeclareAbstractInputPort(
            "cube_estimates", AbstractValue.Make(Estimates(0.0, {}))
        )
        initial = MonitorState(tuple(actions))
        self._state = self.DeclareAbstractState(AbstractValue.Make(initial))
        self.DeclareAbstractOutputPort(
            "action",
            lambda: AbstractValue.Make(ActionCommand(0, None)),
            self._calc_action,
            prerequisites_of_calc={
                self.abstract_state_ticket(self._state),
                self._done_port.ticket(),
            },
        )
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)

    # --- reading -------------------------------------------------------------------------

    def state(self, context) -> MonitorState:
        return context.get_abstract_state(self._state).get_value()

    def error(self, context) -> str | None:
        return self.state(context).error

    def executed(self, context) -> tuple[GroundAction, ...]:
        return self.state(context).emitted

    def measured_facts(self, context):
        """(facts in the domain's names, static facts included; what could not be read)."""
        poses = self._poses_port.Eval(context)
        cubes = {n: poses[i] for n, i in self._bodies.items()}
        X_WG = poses[self._hand] @ self._X_HG
        fingers = float(self._hand_port.Eval(context)[0])
        reading = read_facts(cubes, X_WG=X_WG, finger_opening=fingers)
        lost = lost_cubes(cubes)
        facts = self._roles.from_canonical(reading.facts) | self._static
        return facts, tuple(lost), reading.problems

    # --- deciding ------------------------------------------------------------------------

    def _calc_action(self, context, output) -> None:
        s = self.state(context)
        done = int(round(self._done_port.Eval(context)[0]))
        if s.error is not None or s.seen != done:
            # Being checked (or stopped): an index behind, so nothing starts and the run
            # does not count as finished until the error is read.
            output.set_value(ActionCommand(done if s.error else done - 1, None))
            return
        action = s.plan[s.pos] if s.pos < len(s.plan) else None
        output.set_value(ActionCommand(done, action))

    def _update(self, context, state) -> None:
        s = self.state(context)
        done = int(round(self._done_port.Eval(context)[0]))
        if s.error is None and s.seen == done and self._refusal_port.HasValue(context):
            refusal: Refusal = self._refusal_port.Eval(context)
            if refusal.index == done and s.pos < len(s.plan) and s.plan[s.pos] == refusal.action:
                self._set(state, self._avoid(s, context, done, refusal))
                return
        if s.error is not None or s.seen == done:
            return
        t = context.get_time()
        if self._estimates_port.HasValue(context):
            unseen = self._estimates_port.Eval(context).unseen()
            if unseen:
                self._set(state, replace(s, error=f"the world cannot be recovered: {unseen[0]}"))
                return
        facts, lost, unread = self.measured_facts(context)
        if lost:
            self._set(state, replace(s, error=f"the world cannot be recovered: {lost[0]}"))
            return
        if unread:  # falling or rolling: wait for the world to come to rest
            since = t if s.waiting_since is None else s.waiting_since
            if t - since < SETTLE_WAIT_S:
                self._set(state, replace(s, waiting_since=since))
                return
            self._set(
                state, replace(s, error=f"the world cannot be recovered: {'; '.join(unread)}")
            )
            return
        placed = self._placed(context, s, done, facts)
        if placed is not None:
            s = replace(s, places=s.places + (placed,))
        loose = self._loose(context) if self._re_place_loose else None
        if loose is not None and s.replans < self._max_replans:
            self._set(state, replace(self._re_place(s, t, done, facts, loose), seen=done))
            return
        nominal = s.pos + 1 if s.seen >= 0 else 0
        ks = kernels(self._problem, s.plan)
        i = latest_kernel(ks, facts)
        if nominal < min(s.forced, len(ks)) and ks[nominal] <= facts:
            i = nominal  # a re-place under way: its next action, whatever holds later
        s = replace(s, checks=s.checks + 1, waiting_since=None)
        if i is None:
            s = self._replan(s, t, done, facts, ks[min(nominal, len(ks) - 1)])
        elif i != nominal:
            kind = "skip ahead" if i > nominal else "repeat"
            event = self._event(t, done, kind, s, ks[min(nominal, len(ks) - 1)], facts)
            s = replace(s, pos=i, events=s.events + (event,))
            if kind == "repeat":
                again = s.plan[i]
                tries = s.tries + 1 if s.failing == again else 1
                s = replace(s, failing=again, tries=tries)
                if tries >= MAX_TRIES:
                    s = replace(s, error=f"{again} failed {MAX_TRIES} times in a row (its "
                                f"effects missing each time: {', '.join(event['missing'][:3])}); "
                                "the world cannot be recovered by repeating it")  # fmt: skip
        else:
            s = replace(s, pos=i, failing=None, tries=0)
        if s.error is None and s.pos < len(s.plan):
            s = replace(s, emitted=s.emitted[:done] + (s.plan[s.pos],))
        self._set(state, replace(s, seen=done))

    def _placed(self, context, s: MonitorState, done: int, facts) -> tuple[str, float] | None:
        """The action just ended, if it stacked a cube that stands on its support now, and
        that cube's horizontal offset from the one below (m); None otherwise."""
        if not 0 < done <= len(s.emitted):
            return None
        action = s.emitted[done - 1]
        canonical = self._roles.classify(action).canonical()
        if canonical.name != "stack":
            return None
        cube, support = canonical.args
        if ("on", cube, support) not in self._roles.to_canonical(facts):
            return None
        poses = self._poses_port.Eval(context)
        offset = (
            poses[self._bodies[cube]].translation() - poses[self._bodies[support]].translation()
        )
        return str(action), float(np.linalg.norm(offset[:2]))

    def _loose(self, context) -> tuple[str, str, float] | None:
        """The lowest goal ``on`` fact whose upper cube stands farther than :data:`LOOSE`
        off the lower one (cube, support, offset), with the hand empty; None if none."""
        poses = self._poses_port.Eval(context)
        cubes = {n: poses[i] for n, i in self._bodies.items()}
        X_WG = poses[self._hand] @ self._X_HG
        fingers = float(self._hand_port.Eval(context)[0])
        reading = read_facts(cubes, X_WG=X_WG, finger_opening=fingers)
        if ("arm-empty",) not in reading.facts:
            return None
        offsets = stack_offsets(cubes, reading.facts)
        loose = [
            (f[1], f[2], offsets[f[1]])
            for f in self._goal & reading.facts
            if f[0] == "on" and offsets.get(f[1], 0.0) > LOOSE
        ]
        return min(loose, key=lambda f: cubes[f[0]].translation()[2], default=None)

    def _re_place(self, s: MonitorState, t: float, done: int, facts, loose) -> MonitorState:
        """Set a loose goal stack's upper cube down again: it and the cubes above it put on
        the table, then the planner's plan from there."""
        cube, support, offset = loose
        prefix = list(self._roles.unpile(cube, self._roles.to_canonical(facts)))
        # Taken off and put on the table; the planner then stacks it again from there (a
        # place straight back onto the cube it came from is no move any plan makes, and a
        # learned skill has never been shown it).
        prefix += [self._roles.action(PICK, cube, support), self._roles.action(PLACE, cube)]
        after = frozenset(facts)
        for action in prefix:
            after = apply_action(self._problem, after, action)
        event = {
            "time_s": round(t, 3),
            "after_action": str(s.emitted[done - 1]) if 0 < done <= len(s.emitted) else None,
            "kind": "re-place",
            "why": f"{cube} stands {offset * 1000:.1f} mm off {support}",
        }
        try:
            result = self._planner(dataclasses.replace(self._problem, init=after), None)
            rest = tuple(result.actions if isinstance(result, Plan) else result)
            plan = tuple(prefix) + rest
            check = validate_plan(dataclasses.replace(self._problem, init=frozenset(facts)), plan)
            if not check.ok:
                raise CakeDrakeError(check.message)
        except CakeDrakeError as e:
            return replace(s, events=s.events + (event,),
                           error=f"the world cannot be recovered: no plan sets {cube} down "
                           f"again ({e})")  # fmt: skip
        event["new_plan"] = [str(a) for a in plan]
        emitted = s.emitted[:done] + plan[:1]
        return replace(
            s, plan=plan, pos=0, replans=s.replans + 1, checks=s.checks + 1,
            events=s.events + (event,), emitted=emitted, waiting_since=None,
            forced=len(prefix),
        )  # fmt: skip

    def _replan(self, s: MonitorState, t: float, done: int, facts, expected) -> MonitorState:
        event = self._event(t, done, "replan", s, expected, facts)
        if s.replans >= self._max_replans:
            return replace(
                s,
                events=s.events + (event,),
                error=f"the world cannot be recovered: the replan budget ({self._max_replans}) "
                f"is spent; missing {event['missing'][:3]}",
            )
        problem = dataclasses.replace(self._problem, init=frozenset(facts))
        try:
            result = self._planner(problem, None)
            actions = tuple(result.actions if isinstance(result, Plan) else result)
            check = validate_plan(problem, actions)
            if not check.ok:
                raise CakeDrakeError(check.message)
        except CakeDrakeError as e:
            return replace(
                s,
                events=s.events + (event,),
                error=f"the world cannot be recovered: no plan from the measured facts ({e})",
            )
        event["new_plan"] = [str(a) for a in actions]
        return replace(
            s, plan=actions, pos=0, replans=s.replans + 1, events=s.events + (event,), forced=0
        )

    def _avoid(self, s: MonitorState, context, done: int, refusal: Refusal) -> MonitorState:
        """Replan from the measured facts with ``refusal.action`` forbidden where the world
        is now (the geometric layer found no motion for it)."""
        facts, _, _ = self.measured_facts(context)
        after = str(s.emitted[done - 1]) if 0 < done <= len(s.emitted) else None
        event = {
            "time_s": round(context.get_time(), 3),
            "after_action": after,
            "kind": "infeasible",
            "action": str(refusal.action),
            "reason": refusal.reason,
        }
        forbidden = s.forbidden | {(facts, refusal.action)}
        s = replace(s, events=s.events + (event,), forbidden=forbidden)
        stop = f"the world cannot be recovered: {refusal.reason}"
        if s.replans >= self._max_replans:
            return replace(s, error=f"{stop}; the replan budget ({self._max_replans}) is spent")
        problem = dataclasses.replace(self._problem, init=frozenset(facts))
        try:
            actions = self._plan_avoiding(problem, forbidden)
        except CakeDrakeError as e:
            return replace(s, error=f"{stop}; no plan avoids it ({e})")
        event["new_plan"] = [str(a) for a in actions]
        emitted = s.emitted[:done] + actions[:1]
        return replace(s, plan=actions, pos=0, replans=s.replans + 1, emitted=emitted, forced=0)

    def _plan_avoiding(self, problem: Problem, forbidden) -> tuple[GroundAction, ...]:
        """A valid plan from ``problem.init`` that never takes an action where it is
        forbidden: the planner's own, else the shortest of (an allowed first action, then
        the planner's plan from where it leads)."""

        def plan(p: Problem) -> tuple[GroundAction, ...] | None:
            result = self._planner(p, None)
            actions = tuple(result.actions if isinstance(result, Plan) else result)
            check = validate_plan(p, actions)
            if not check.ok:
                raise CakeDrakeError(check.message)
            return None if _meets_forbidden(p, actions, forbidden) else actions

        state = problem.init
        first = plan(problem)
        if first is not None:
            return first
        best = None
        for op in ground_all(problem):
            if (state, op.action) in forbidden or not op.applicable(state):
                continue
            try:
                rest = plan(dataclasses.replace(problem, init=op.apply(state)))
            except CakeDrakeError:
                continue
            if rest is not None and (best is None or len(rest) + 1 < len(best)):
                best = (op.action, *rest)
        if best is None:
            raise CakeDrakeError("each plan found takes it where it was refused")
        return best

    def _event(self, t, done, kind, s: MonitorState, expected, facts) -> dict:
        after = str(s.emitted[done - 1]) if 0 < done <= len(s.emitted) else None
        missing = sorted(expected - facts)
        touched = {a for f in missing for a in f[1:]}
        return {
            "time_s": round(t, 3),
            "after_action": after,
            "kind": kind,
            "missing": [fact_str(f) for f in missing],
            "measured": [
                fact_str(f)
                for f in sorted(facts - expected)
                if f not in self._static and set(f[1:]) & touched
            ],
        }

    def _set(self, state, value: MonitorState) -> None:
        state.get_mutable_abstract_state(self._state).set_value(value)
