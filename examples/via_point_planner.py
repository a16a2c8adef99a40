"""A motion planner of your own (the geometric layer): one via point.

The simplest planner that can go around something: draw configurations around the
midpoint of the blocked move, ever wider, until one is free and both straight moves to
it (from the start, then on to the goal) are free. Deterministic: the draws come from the
query's seed.

A scenario names the factory (``motion: {planner: examples.via_point_planner:make}``);
the geometric layer calls ``plan(query)`` only for a move whose straight line is blocked
and checks the path it returns (see :mod:`cake_drake.geometric.planners`).
"""

from __future__ import annotations

import numpy as np

from cake_drake.geometric.planners import MoveQuery


class ViaPoint:
    name = "via-point"

    def __init__(self, tries: int = 3000, spread: float = 0.3) -> None:
        self.tries = tries
        self.spread = spread  # rad, the first draws' standard deviation

    def plan(self, query: MoveQuery) -> np.ndarray | str:
        rng = np.random.default_rng(query.seed)
        middle = (query.start + query.goal) / 2
        for k in range(self.tries):
            sigma = self.spread * (1 + k / 300)  # ever wider
            via = np.clip(middle + rng.normal(0.0, sigma, 7), query.lower, query.upper)
            if (
                query.is_free(via)
                and self._free(query, query.start, via)
                and self._free(query, via, query.goal)
            ):
                return np.array([query.start, via, query.goal])
        return f"no free via point in {self.tries} draws"

    @staticmethod
    def _free(query: MoveQuery, a: np.ndarray, b: np.ndarray) -> bool:
        """Every configuration along a -> b, ``query.resolution`` apart (joint-space
        distance), is free."""
        n = max(2, int(np.ceil(np.linalg.norm(b - a) / query.resolution)) + 1)
        return all(query.is_free(a + s * (b - a)) for s in np.linspace(0.0, 1.0, n)[1:-1])


def make() -> ViaPoint:
    """The factory a scenario names."""
    return ViaPoint()
