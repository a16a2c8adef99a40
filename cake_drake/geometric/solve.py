"""The exercise's ``solve_action(action, world)``: waypoints -> IK -> joint trajectory."""

from __future__ import annotations

import math
import time
import zlib
from dataclasses import dataclass, field, replace

import numpy as np
from pydrake.math import RigidTransform

from cake_drake.errors import IkError
from cake_drake.geometric.collisions import (
    FINGERS_HOLDING,
    FINGERS_OPEN,
    Collision,
    CollisionChecker,
    action_collisions,
)
from cake_drake.geometric.free_space import FreeSpace
from cake_drake.geometric.ik import IkSolver
from cake_drake.geometric.planners import QUERY_BUDGET_S, MoveQuery, ask
from cake_drake.geometric.trajectory import (
    GRIPPER_CLOSED,
    GRIPPER_OPEN,
    PHASE_NAMES,
    JointTrajectory,
    Timing,
)
from cake_drake.geometric.waypoints import (
    PLACE_ACTIONS,
    Waypoint,
    WaypointParams,
    WorldView,
    waypoints_for,
)
from cake_drake.plugins import DURING, PluginError, guarded
from cake_drake.symbolic import GroundAction


@dataclass(frozen=True)
class Motion:
    """What :func:`solve_action` planned for one action."""

    waypoints: tuple[Waypoint, ...]
    solutions: tuple[np.ndarray, ...]  # IK solution of each waypoint
    collisions: tuple[tuple[str, Collision], ...] = ()  # (phase, collision), if checked
    transit_clearance: float = 0.0  # the clearance the motion was planned with (m)
    #: The waypoint parameters the motion was planned with (the collision-free variant).
    params: WaypointParams = field(default_factory=WaypointParams)
    #: The phase after which the moves still have to be planned again from the world as
    #: it is measured then (:func:`refine_action`); None when every move was appended.
    pending_after: str | None = None

    def warnings(self, index: int, action: GroundAction) -> list[str]:
        """One line per collision, naming the action and the phase."""
        return [f"action {index + 1} {action}, {phase}: {c}" for phase, c in self.collisions]


#: What --avoid-collisions tries, in order, until a motion hits nothing: the transit
#: height raised by these amounts (m), each with the gripper at its comfortable yaw and
#: turned a quarter (the hand is wide along its fingers).
AVOID_RAISES = (0.0, 0.05, 0.10)
AVOID_TURNS = (0, 1)


#: A place is planned whole when its action starts (so that an unreachable pose or a
#: collision is found before the arm moves), but only moved up to this phase: the rest
#: is planned again from the poses measured there (:func:`refine_action`). A cube creeps
#: in a friction grasp while it is carried (millimetres over a long transport, see
#: docs/world.md); measured above the target, the creep is corrected before it lands.
REFINE_AFTER = "transport"


#: Moves between two poses at the transit height, far apart around the base.
TRANSIT_PHASES = ("pre-grasp", "transport")


#: rad, the Panda's joint-1 limit (datasheet).
Q1_LIMIT = 2.8973


def _swing_seed(q: np.ndarray, p_from: np.ndarray, p_to: np.ndarray) -> np.ndarray:
    """``q`` turned about joint 1 by the change in azimuth from ``p_from`` to ``p_to``.

    The Panda is symmetric about its first joint, so this is (nearly) the solution for
    the target, and the joint-space move to it swings the hand around the base at a
    constant height. Seeded from ``q`` itself, IK may land on another arm posture (the
    elbow elsewhere, or joint 1 the long way round), and the straight joint-space move
    between the two postures dips the hand by up to 7 cm: into a 10-high tower.
    """
    turn = math.atan2(p_to[1], p_to[0]) - math.atan2(p_from[1], p_from[0])
    turn = (turn + math.pi) % (2 * math.pi) - math.pi
    seed = np.array(q, float)
    seed[0] += turn
    return seed if abs(seed[0]) <= Q1_LIMIT else np.array(q, float)


def _solve(ik: IkSolver, wp: Waypoint, q_seed, action, index: int) -> np.ndarray:
    """IK for one waypoint, or an :class:`IkError` naming the action, phase and pose."""
    q = ik.solve(wp.X_WG, q_seed)
    if q is None:
        p = np.round(wp.X_WG.translation(), 3).tolist()
        raise IkError(
            f"action {index + 1} {action}: no IK solution ({ik.name}) for the "
            f"{wp.phase} pose at {p} m (gripper pointing down); the cube may be out of reach"
        )
    return q


def _solve_all(action, index, world, ik, q_start, params, after=None):
    """The waypoints of ``action`` after phase ``after`` (all when None) and their IK
    solutions, each seeded from the one before (the first from ``q_start``)."""
    waypoints = waypoints_for(action, world, params)
    if after is not None:
        waypoints = waypoints[[w.phase for w in waypoints].index(after) + 1 :]
    solutions = []
    q_seed = q_start
    p_seed = world.X_WG.translation()  # where the hand is at q_seed
    for wp in waypoints:
        if wp.phase in TRANSIT_PHASES:
            q_seed = _swing_seed(q_seed, p_seed, wp.X_WG.translation())
        q = _solve(ik, wp, q_seed, action, index)
        solutions.append(q)
        q_seed, p_seed = q, wp.X_WG.translation()
    return tuple(waypoints), tuple(solutions)


def _append(
    trajectory,
    waypoints,
    solutions,
    index,
    timing,
    until=None,
    release=True,
    vias=None,
    stops=frozenset(),
):
    """Append the moves to ``solutions``, up to and including phase ``until`` (all when
    None), each gripper change after a settle. ``vias`` maps a move's index to the
    configurations it passes through (a planned path), moved through without blending;
    the moves in ``stops`` do not blend into the one before either. With ``release``
    False the fingers keep their command at ``until``."""
    stop = replace(timing, blend=0.0)
    for k, (wp, q) in enumerate(zip(waypoints, solutions, strict=True)):
        path = (vias or {}).get(k)
        if path is not None:
            for via in path:
                trajectory.move(via, wp.phase, index, stop)
            trajectory.move(q, wp.phase, index, stop)
        else:
            trajectory.move(q, wp.phase, index, stop if k in stops else timing)
        want = GRIPPER_OPEN if wp.gripper == "open" else GRIPPER_CLOSED
        if want != trajectory.end_gripper:
            trajectory.hold(timing.settle_time, wp.phase, index)
            if release or wp.phase != until:
                trajectory.hold(timing.gripper_time, wp.phase, index, gripper=want)
        if wp.phase == until:
            break


def _plan(
    action, index, world, ik, trajectory, timing, params, after=None, until=None, release=True
):
    """IK for the waypoints after phase ``after`` (all when None); moves appended up to
    and including phase ``until`` (all when None). With ``release`` False the fingers
    keep their command at ``until`` (only the settle is held)."""
    waypoints, solutions = _solve_all(action, index, world, ik, trajectory.end_q, params, after)
    _append(trajectory, waypoints, solutions, index, timing, until, release)
    return waypoints, solutions


class Infeasible(IkError):
    """No motion does the action where the world is now: no IK, no free grasp or place
    pose under any turn of the hand, or no free path within the planner's budget."""


@dataclass
class Planning:
    """What chooses motions that hit nothing (a ``motion.planner`` other than ``straight``)."""

    space: FreeSpace
    planner: object  # has name and plan(query) (cake_drake.geometric.planners)
    spec: str
    seed: int  # the scenario's
    limits: tuple[np.ndarray, np.ndarray]  # the arm's joint limits (lower, upper)
    budget_s: float = QUERY_BUDGET_S
    #: One entry per planner query: (action index, phase, ms, path length / straight).
    queries: list = field(default_factory=list)


#: Quarter turns of the hand tried at a grasp or a place, today's first.
GRASP_TURNS = (0, 1)
#: The phases whose end pose touches the action's own cubes.
CONTACT_PHASES = ("grasp", "place")


def _move_worlds(action, world: WorldView, waypoints, params):
    """For each move of the action, how :meth:`FreeSpace.set` is called: the cube poses,
    finger opening, the held cube and its grasp, the cubes the robot may touch.

    The cube rides in the hand from the grasp (a pick) or from the start (a place) until the
    fingers open, and stays where the place sets it; the action's own cubes may be touched
    on the moves down to them and up from them (not on the transits at the safe height)."""
    block = action.args[0]
    poses = dict(world.cube_poses)
    if action.name in PLACE_ACTIONS:
        held, X_GB = block, world.X_WG.inverse() @ world.cube_poses[block]
    else:
        held, X_GB = None, None
    out = []
    for wp in waypoints:
        touching = () if wp.phase in TRANSIT_PHASES else tuple(action.args)
        fingers = FINGERS_OPEN if held is None else FINGERS_HOLDING
        out.append((dict(poses), fingers, held, X_GB, touching))
        if wp.gripper == "closed" and held is None:
            held, X_GB = block, wp.X_WG.inverse() @ poses[block]
        elif wp.gripper == "open" and held is not None:
            poses[block] = wp.X_WG @ X_GB
            held = X_GB = None
    return out


def _seed(planning: Planning, index: int, variant: int, move: int) -> int:
    """The seed of one query: from the scenario's seed, the action, the variant and the
    move; never 0 (OMPL's "pick one yourself")."""
    text = f"{planning.seed}/{index}/{variant}/{move}".encode()
    return zlib.crc32(text) % (2**31 - 1) + 1


def _planned(action, index, world, ik, start, timing, params, until, planning: Planning):
    """The first collision-free motion of ``action``: the hand at today's yaw, then turned
    a quarter; for a put-down, each free table slot in turn. The grasp or place pose must be
    free; a blocked move is planned (:func:`_path`). Returns (Motion, trajectory), or
    raises :class:`Infeasible` with every variant's reason."""
    slots = [None]
    if action.name == "put-down":
        slots = [(x, y) for x, y in world.slots if _slot_free(world, action.args[0], params, x, y)]
    reasons = []
    variant = 0
    for slot in slots:
        view = world if slot is None else replace(world, slots=(slot,))
        for turn in GRASP_TURNS:
            variant += 1
            p = replace(params, yaw_turns=params.yaw_turns + turn)
            where = f"hand turned {turn}/4" + ("" if slot is None else f", slot {slot}")
            try:
                waypoints, solutions = _solve_all(action, index, view, ik, start.end_q, p)
            except IkError as e:
                reasons.append(f"{where}: {str(e).split(': ', 1)[-1]}")
                continue
            worlds = _move_worlds(action, view, waypoints, p)
            vias, why = {}, None
            q0 = start.end_q
            for k, (wp, q1, w) in enumerate(zip(waypoints, solutions, worlds, strict=True)):
                planning.space.set(*w)
                if wp.phase in CONTACT_PHASES and not planning.space.is_free(q1):
                    hit = planning.space.nearest_hit(q1)
                    why = f"{where}: the {wp.phase} pose is not free" + (
                        f" ({hit[0]} {hit[2] * 1000:.1f} mm from {hit[1]})" if hit else ""
                    )
                    break
                if not planning.space.edge_is_free(q0, q1):
                    seed = _seed(planning, index, variant, k)
                    path = _path(planning, index, wp.phase, q0, q1, seed)
                    if isinstance(path, str):
                        why = f"{where}: {wp.phase} move: {path}"
                        break
                    vias[k] = path[1:-1]
                q0 = q1
            if why is not None:
                reasons.append(why)
                continue
            stops: set[int] = set()
            while True:  # a blend cuts a corner: re-checked, and a stop where it hits
                trajectory = start.copy()
                _append(trajectory, waypoints, solutions, index, timing, until, True, vias,
                        frozenset(stops))  # fmt: skip
                hits = _blend_hits(planning.space, trajectory, len(start.segments), waypoints,
                                   worlds) - stops  # fmt: skip
                if not hits:
                    break
                stops |= hits
            motion = Motion(waypoints, solutions, (), p.transit_clearance, p, until)
            return motion, trajectory
    if not slots:
        reasons.append("every table slot is taken")
    why = "; ".join(reasons)
    raise Infeasible(f"action {index + 1} {action}: no collision-free motion ({why})")


#: s between the configurations checked where two moves blend.
BLEND_CHECK_STEP = 0.005


def _blend_hits(space, trajectory, first: int, waypoints, worlds) -> set[int]:
    """The moves (by waypoint index) whose blend into the move before them is not free:
    the blended corner leaves the two straight lines that were checked."""
    phases = {PHASE_NAMES.index(w.phase): k for k, w in enumerate(waypoints)}
    segments = trajectory.segments
    hits = set()
    for i in range(max(first, 1), len(segments)):
        seg, prev = segments[i], segments[i - 1]
        if not (seg.moves and prev.moves and seg.t0 < prev.end - 1e-9):
            continue
        k = phases[seg.phase]
        space.set(*worlds[k])
        for t in np.arange(seg.t0, prev.end, BLEND_CHECK_STEP):
            if not space.is_free(trajectory.at(float(t))[0]):
                hits.add(k)
                break
    return hits


def _slot_free(world: WorldView, held: str, params: WaypointParams, x: float, y: float) -> bool:
    return all(
        np.hypot(X.translation()[0] - x, X.translation()[1] - y) > params.slot_clearance
        for n, X in world.cube_poses.items()
        if n != held
    )


def _path(planning: Planning, index: int, phase: str, q0, q1, seed: int):
    """A free path q0 -> q1 from the planner (its every segment checked), or the reason.
    A move whose start or goal is itself in collision has none, whatever the planner: it
    is this layer's reason, and the planner is not asked."""
    space = planning.space
    for end, q in (("start", q0), ("goal", q1)):
        if not space.is_free(q):
            hit = space.nearest_hit(q)
            return f"its {end} is not free" + (
                f" ({hit[0]} {hit[2] * 1000:.1f} mm from {hit[1]})" if hit else ""
            )
    lower, upper = planning.limits
    query = MoveQuery(np.array(q0), np.array(q1), space.is_free, lower, upper, seed,
                      planning.budget_s, space.resolution)  # fmt: skip
    t0 = time.perf_counter()
    answer = ask(planning.planner, planning.spec, query)
    ms = (time.perf_counter() - t0) * 1000
    if isinstance(answer, str):
        planning.queries.append((index, phase, ms, None))
        return answer
    for a, b in zip(answer[:-1], answer[1:], strict=True):
        if not space.edge_is_free(a, b):
            raise PluginError(
                f"motion planner {planning.spec!r} returned a path through a collision "
                f"(action {index + 1}, {phase} move)",
                DURING,
            )
    length = float(np.sum(np.linalg.norm(np.diff(answer, axis=0), axis=1)))
    planning.queries.append((index, phase, ms, length / max(np.linalg.norm(q1 - q0), 1e-9)))
    return answer


def solve_action(
    action: GroundAction,
    index: int,
    world: WorldView,
    ik: IkSolver,
    trajectory: JointTrajectory,
    timing: Timing = Timing(),
    params: WaypointParams = WaypointParams(),
    checker: CollisionChecker | None = None,
    avoid_collisions: bool = False,
    refine: bool = False,
    planning: Planning | None = None,
) -> Motion:
    """Append ``action``'s motion to ``trajectory``: waypoints, IK, timed moves.

    With ``planning`` (a motion planner other than ``straight``) the motion is chosen
    among collision-free ones instead (:func:`_planned`): an action with none raises
    :class:`Infeasible`.

    With ``refine``, a place action is planned whole but moved only up to
    :data:`REFINE_AFTER`; ``Motion.pending_after`` then says that the rest is to be
    planned by :func:`refine_action` once the arm is there.

    Every waypoint's IK is seeded from the previous solution, so consecutive poses stay
    on one branch of the arm's kinematics. Raises :class:`IkError` naming the action,
    the phase and the pose when a waypoint has no solution.

    With a ``checker`` every move is checked for collisions with cubes other than the
    action's own and with the table (the symbolic plan knows no geometry); they are
    returned, to be reported. With ``avoid_collisions`` the motion is planned again,
    with the transit height raised and the gripper turned a quarter
    (:data:`AVOID_RAISES` x :data:`AVOID_TURNS`), until one hits nothing; if none is
    free, the one with the shallowest collisions is kept and its collisions returned.
    """
    start = trajectory.copy()
    until = REFINE_AFTER if refine and action.name in PLACE_ACTIONS else None
    if planning is not None:
        motion, planned = _planned(action, index, world, ik, start, timing, params, until, planning)
        if checker is not None:  # the report's own, independent check of what will run
            found = action_collisions(checker, action, world, motion.waypoints, start.end_q,
                                      motion.solutions)  # fmt: skip
            motion = replace(motion, collisions=tuple(found))
        trajectory.assign(planned)
        return motion
    variants = [(0.0, 0)]
    if checker is not None and avoid_collisions:
        variants = [(dz, turn) for dz in AVOID_RAISES for turn in AVOID_TURNS]
    best = None
    first_error = None
    for dz, turn in variants:
        p = replace(
            params,
            transit_clearance=params.transit_clearance + dz,
            yaw_turns=params.yaw_turns + turn,
        )
        candidate = start.copy()
        try:
            waypoints, solutions = _plan(
                action, index, world, ik, candidate, timing, p, until=until
            )
        except IkError as e:  # another variant may still reach: keep the first error
            first_error = first_error or e
            continue
        found = ()
        if checker is not None:
            found = tuple(
                action_collisions(checker, action, world, waypoints, start.end_q, solutions)
            )
        depth = sum(c.depth for _, c in found)
        if best is None or depth < best[0]:
            motion = Motion(waypoints, solutions, found, p.transit_clearance, p, until)
            best = (depth, candidate, motion)
        if not found:
            break
    if best is None:
        raise first_error
    trajectory.assign(best[1])
    return best[2]


#: The place is planned in two more steps: from above the target, the move down to the
#: place pose (fingers closed); there, the release (:func:`release_action`).
PLACE = "place"
#: m: a hand that stands this far (xy) off its command at the place pose is moved by
#: that much before the fingers open; closer, it opens where it is.
RELEASE_CORRECTION = 0.0005


def refine_action(
    action: GroundAction,
    index: int,
    world: WorldView,
    ik: IkSolver,
    trajectory: JointTrajectory,
    timing: Timing,
    params: WaypointParams,
    after: str = REFINE_AFTER,
) -> Motion:
    """Plan the moves of ``action`` after phase ``after`` again, from the world measured
    now (``params`` as :func:`solve_action` chose them): the place pose from where the
    cube sits in the hand *now* and from the support's pose now. Appends the move down to
    the place pose, fingers still closed; ``Motion.pending_after`` is then ``"place"``
    and ``Motion.waypoints[0]`` the commanded place pose (see :func:`release_action`)."""
    above = replace(params, place_drop=params.place_drop + params.release_height)
    waypoints, solutions = _plan(
        action, index, world, ik, trajectory, timing, above, after, until=PLACE, release=False
    )
    return Motion(waypoints, solutions, (), params.transit_clearance, params, PLACE)


def release_action(
    action: GroundAction,
    index: int,
    world: WorldView,
    ik: IkSolver,
    trajectory: JointTrajectory,
    timing: Timing,
    params: WaypointParams,
    X_commanded: RigidTransform,
) -> Motion:
    """Just above the place pose, fingers closed: set the cube down where it belongs,
    open the fingers, retract.

    A controller may hold the hand a little off its command (the computed-torque
    controller's model lacks the cube: 1.7 mm towards the base, steadily, at every
    place). Measured here, with the cube's pose in the hand and the support's, that
    offset is taken off the command of the last move, which lowers the cube by
    ``params.release_height`` to ``params.place_drop`` above its support: the cube lands
    where it belongs instead of a step aside at every level, and drops only 0.5 mm (an
    off-centre cube falling 2 mm pivots in the opening fingers and rocks the tower).
    The correction is made with the cube still clear of its support (at 0.5 mm the
    support's friction would hold it back).
    """
    waypoints = list(waypoints_for(action, world, params))
    k = [w.phase for w in waypoints].index(PLACE)
    place, retract = waypoints[k], waypoints[k + 1]
    error = world.X_WG.translation() - X_commanded.translation()
    if params.release_height > 0 or np.linalg.norm(error) > RELEASE_CORRECTION:
        place = replace(
            place, X_WG=RigidTransform(place.X_WG.rotation(), place.X_WG.translation() - error)
        )
        retract = replace(
            retract,
            X_WG=RigidTransform(retract.X_WG.rotation(), retract.X_WG.translation() - error),
        )
        q = _solve(ik, place, trajectory.end_q, action, index)
        trajectory.move(q, PLACE, index, timing)
        trajectory.hold(timing.settle_time, PLACE, index)
    trajectory.hold(timing.gripper_time, PLACE, index, gripper=GRIPPER_OPEN)
    q = _solve(ik, retract, trajectory.end_q, action, index)
    trajectory.move(q, retract.phase, index, timing)
    return Motion((place, retract), (q,), (), params.transit_clearance, params)


#: Wall-clock budget of one call to a user's IK solver (s): tabletop waypoints take
#: milliseconds; a solver still busy after this is not coming back.
IK_BUDGET_S = 10.0


class TimedSolver:
    """Wraps an :class:`IkSolver` and records the wall time of every solve (ms)."""

    def __init__(self, solver: IkSolver, spec: str | None = None, limits=None) -> None:
        """``spec``: the ``module:attribute`` of a user's solver, whose every call is then
        guarded (:func:`cake_drake.plugins.guarded`, :data:`IK_BUDGET_S` a call) and whose
        answers are checked: seven finite angles within ``limits`` (lower, upper), or None."""
        self.solver = solver
        self.name = solver.name
        self.times_ms: list[float] = []
        self.spec = spec
        self.limits = limits

    def solve(self, X_WG, q_seed):
        t0 = time.perf_counter()
        try:
            if self.spec is None:
                return self.solver.solve(X_WG, q_seed)
            label = f"IK solver {self.spec!r}"
            q = guarded(
                label, self.solver.solve, X_WG, q_seed, exit_code=DURING, budget_s=IK_BUDGET_S
            )
            return None if q is None else self._checked(q, label)
        finally:
            self.times_ms.append((time.perf_counter() - t0) * 1000)

    def _checked(self, q, label: str) -> np.ndarray:
        try:
            q = np.asarray(q, dtype=float)
        except (TypeError, ValueError):
            raise PluginError(
                f"{label} returned {type(q).__name__} {q!r:.60}; it returns 7 joint angles "
                "(rad) or None",
                DURING,
            ) from None
        why = None
        if q.shape != (7,):
            why = f"an array of shape {q.shape}, not 7 joint angles"
        elif not np.all(np.isfinite(q)):
            why = f"non-finite angles {np.round(q, 3).tolist()}"
        elif self.limits is not None:
            lo, hi = self.limits
            out = [i + 1 for i in range(7) if not lo[i] - 1e-6 <= q[i] <= hi[i] + 1e-6]
            if out:
                j = out[0] - 1
                why = f"joint {out[0]} at {q[j]:g} rad, outside its limits [{lo[j]:g}, {hi[j]:g}]"
        if why:
            raise PluginError(f"{label} returned {why}; it returns 7 joint angles or None", DURING)
        return q
