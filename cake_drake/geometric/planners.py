"""Motion planners: a path for a move whose straight joint-space line is blocked.

The exercise moves the arm in straight joint-space lines between the waypoints' IK
solutions, enough for a tidy table (``straight``, the default: a blocked move is kept and
its collisions reported, the lesson of the crowded table). ``rrt-connect`` (Kuffner &
LaValle, 2000, OMPL's implementation) searches for a free path instead, and shortens it;
``module:attribute`` names a factory ``() -> planner`` of your own.

The protocol: a planner has a ``name`` and ``plan(query) -> path | reason``, where
``query`` is a :class:`MoveQuery` (start, goal, the collision query, joint limits, the
seed and the budget) and ``path`` an (N, 7) array of configurations from ``start`` to
``goal`` whose straight segments are free, or a string saying why there is none. The
geometric layer asks only for moves that are blocked and whose start and goal are both
free (a move that ends in collision has no free path: the layer says so itself, and the
action is infeasible as when a planner finds none), checks the answer (shape, ends,
limits, every segment free) and then times it like every other move.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from cake_drake.errors import InputError
from cake_drake.plugins import DURING, PluginError, guarded, require, resolve

#: The planners shipped; ``module:attribute`` names your own.
PLANNERS = ("straight", "rrt-connect")
#: s of wall clock a planner has for one move (the seed's RRT-Connect needs ~10 ms).
QUERY_BUDGET_S = 2.0
OMPL_PIP = "pip install 'cake_drake[motion]'  (or: pip install ompl)"


@dataclass(frozen=True)
class MoveQuery:
    """One blocked move, as a planner is asked it."""

    start: np.ndarray  # (7,) rad
    goal: np.ndarray  # (7,) rad
    is_free: Callable[[np.ndarray], bool]  # is the arm free at this configuration?
    lower: np.ndarray  # (7,) joint limits, rad
    upper: np.ndarray
    seed: int  # nonzero; the same query and seed give the same path
    budget_s: float  # wall clock for this query
    resolution: float  # rad, the step at which a segment's freedom is checked


class RrtConnect:
    """OMPL's RRT-Connect on the arm's seven joints, then two of OMPL's shortcuts
    (``reduceVertices``, then ``ropeShortcutPath``): measured between crowded towers, a
    fifth of the time of ``simplifyMax`` (19 against 73 ms a query, median) for paths 1.22
    against 1.10 times the straight line. ``range_rad`` is the longest edge the trees grow
    by: OMPL's default (a fifth of the space's extent, ~2.6 rad here) gives paths several
    times longer."""

    name = "rrt-connect"

    def __init__(self, range_rad: float = 0.5) -> None:
        require_ompl()
        self.range_rad = range_rad

    def plan(self, query: MoveQuery) -> np.ndarray | str:
        from ompl import base as ob
        from ompl import geometric as og
        from ompl import util as ou

        ou.setLogLevel(ou.LogLevel.LOG_NONE)
        ou.RNG.setSeed(int(query.seed))  # before the objects that draw from it exist
        space = ob.RealVectorStateSpace(7)
        bounds = ob.RealVectorBounds(7)
        for i in range(7):
            bounds.setLow(i, float(query.lower[i]))
            bounds.setHigh(i, float(query.upper[i]))
        space.setBounds(bounds)
        setup = og.SimpleSetup(space)
        is_free = query.is_free

        def valid(state) -> bool:
            return bool(is_free(np.array([state[i] for i in range(7)])))

        setup.setStateValidityChecker(valid)
        info = setup.getSpaceInformation()
        info.setStateValidityCheckingResolution(query.resolution / space.getMaximumExtent())
        planner = og.RRTConnect(info)
        planner.setRange(self.range_rad)
        setup.setPlanner(planner)
        start, goal = space.allocState(), space.allocState()
        for i in range(7):
            start[i], goal[i] = float(query.start[i]), float(query.goal[i])
        setup.setStartAndGoalStates(start, goal)
        setup.solve(query.budget_s)
        if not setup.haveExactSolutionPath():
            return f"RRT-Connect found no free path in {query.budget_s:g} s"
        path = setup.getSolutionPath()
        simplifier = setup.getPathSimplifier()
        simplifier.reduceVertices(path)
        simplifier.ropeShortcutPath(path)
        states = path.getStates()
        return np.array([[s[i] for i in range(7)] for s in states])


def require_ompl() -> None:
    """Refuse ``rrt-connect`` where OMPL is not installed, with the line that installs it."""
    try:
        import ompl.geometric  # noqa: F401
    except ImportError:
        raise InputError(
            f"motion planner 'rrt-connect' needs OMPL, which is not installed: {OMPL_PIP}"
        ) from None


_REGISTRY: dict[str, Callable] = {"rrt-connect": RrtConnect}


def make_planner(spec: str):
    """The planner ``spec`` names (None for ``straight``: no planning), checked for the
    protocol's ``name`` and ``plan``."""
    if spec == "straight":
        return None
    planner = resolve(spec, _REGISTRY, "motion planner")()
    require(planner, spec, "motion planner", ("name", "plan"))
    return planner


def ask(planner, spec: str, query: MoveQuery) -> np.ndarray | str:
    """``planner.plan(query)``, guarded and checked (:func:`check_path`; the caller checks
    that every segment is free), or the planner's reason."""
    label = f"motion planner {spec!r}"
    if spec in PLANNERS:
        answer = planner.plan(query)
    else:
        answer = guarded(
            label, planner.plan, query, exit_code=DURING, budget_s=query.budget_s + 5.0
        )
    if isinstance(answer, str):
        return answer
    return check_path(answer, query, label)


def _ends_match(path: np.ndarray, query: MoveQuery) -> bool:
    return np.allclose(path[0], query.start, atol=1e-6) and np.allclose(
        path[-1], query.goal, atol=1e-6
    )


def check_path(answer, query: MoveQuery, label: str) -> np.ndarray:
    """``answer`` as an (N, 7) path, or a :class:`PluginError` saying what is wrong."""
    try:
        path = np.asarray(answer, dtype=float)
    except (TypeError, ValueError):
        path = None
    why = None
    if path is None or path.ndim != 2 or path.shape[1] != 7 or len(path) < 2:
        shape = "no array" if path is None else f"an array of shape {path.shape}"
        why = f"{shape}, not an (N >= 2, 7) path or a reason"
    elif not np.all(np.isfinite(path)):
        why = "non-finite angles"
    elif not _ends_match(path, query):
        why = "a path that does not run from the query's start to its goal"
    elif np.any(path < query.lower - 1e-6) or np.any(path > query.upper + 1e-6):
        why = "a path outside the joint limits"
    if why:
        raise PluginError(f"{label} returned {why}", DURING)
    path[0], path[-1] = query.start, query.goal
    return path
