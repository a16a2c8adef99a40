"""Motion-planner benchmark: the crowded table (slot radius 0.4 m, towers 10.4 cm apart)
under ``straight`` and ``rrt-connect``, on problem_5 and on seeded generated problems.

Per planner: towers built; collisions of the executed moves found by the run's own
collision report (SceneGraph penetration, every 0.02 rad of every move; a check
independent of the planner's checker); the monitor's disagreements with the plan (a
knocked cube shows as one); motion-planner queries (blocked moves), their time (median,
p90) and path length against the blocked straight line; the simulated run's wall time
against ``straight``.

(b) blocked moves: seeded pairs of hand poses just above two towers of a crowded table
    (towers of 1 to 3 cubes), kept when both ends are free and the straight move between
    them is not; each planner's success, time per query (median, p90, wall clock of this
    process) and path length against the straight line.

    python benchmarks/motion.py [--seeds 10] [--queries 50]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from machine import machine  # benchmarks/machine.py
from pydrake.math import RigidTransform

from cake_drake.geometric.free_space import FreeSpace
from cake_drake.geometric.ik import Kinematics, make_solver
from cake_drake.geometric.planners import MoveQuery, ask, make_planner
from cake_drake.geometric.waypoints import gripper_down
from cake_drake.pipeline import run
from cake_drake.scenario import Generate, Scenario
from cake_drake.world.scene import Q_HOME, WorldConfig


def crowded(problem: Generate | None, planner: str) -> Scenario:
    s = Scenario()
    s.world.slot_radius = 0.4
    s.world.slot_spacing = s.world.slot_spacing_max = 0.104
    s.motion.planner = planner
    if problem is not None:
        s.task.generate = problem
    return s


def blocked_queries(count: int, seed: int = 0):
    """(space, queries): ``count`` blocked moves on a crowded table (see the module)."""
    rng = np.random.default_rng(seed)
    world = WorldConfig(slot_radius=0.4, slot_spacing=0.104, slot_spacing_max=0.104)
    slots = world.slots_for(6)
    poses, tops, n = {}, [], 0
    for x, y in slots:
        height = int(rng.integers(1, 4))
        for level in range(height):
            poses[f"c{n}"] = RigidTransform([x, y, 0.02 + 0.04 * level])
            n += 1
        tops.append(0.04 * height)
    space = FreeSpace(sorted(poses))
    space.set(poses, 0.04)
    kin = Kinematics()
    ik = make_solver("drake", kin, 0)
    queries = []
    while len(queries) < count:
        i, j = rng.choice(len(slots), 2, replace=False)
        ends = []
        for k in (i, j):
            z = tops[k] + 0.02 + rng.uniform(0.0, 0.04)
            yaw = rng.uniform(-np.pi / 4, np.pi / 4)
            ends.append(ik.solve(RigidTransform(gripper_down(yaw), [*slots[k], z]), Q_HOME))
        q0, q1 = ends
        if q0 is None or q1 is None or not (space.is_free(q0) and space.is_free(q1)):
            continue
        if space.edge_is_free(q0, q1):
            continue
        seed = len(queries) + 1
        queries.append(MoveQuery(q0, q1, space.is_free, kin.lower, kin.upper, seed, 2.0, 0.02))
    return space, queries


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=10, help="generated problems")
    parser.add_argument("--queries", type=int, default=50, help="blocked moves in (b)")
    args = parser.parse_args()
    problems = [None] + [
        Generate(blocks=n, seed=k) for n in (4, 6, 8) for k in range(args.seeds // 3 + 1)
    ][: args.seeds]
    print(machine())
    print(f"(a) crowded table, problem_5 and {len(problems) - 1} generated problems of 4-8 blocks")
    header = (
        f"{'planner':<13}{'built':>7}{'collisions':>12}{'disagreements':>15}{'queries':>9}"
        f"{'median ms':>11}{'p90 ms':>8}{'path/line':>11}{'wall vs straight':>18}"
    )
    print(header)
    walls: dict[str, list[float]] = {}
    for planner in ("straight", "rrt-connect"):
        built = hits = disagreements = 0
        ms, ratios, wall = [], [], []
        for problem in problems:
            t0 = time.perf_counter()
            result = run(crowded(problem, planner), write=False)
            wall.append(time.perf_counter() - t0)
            built += result.success
            hits += len(result.execution.warnings)
            disagreements += len(result.execution.monitoring.get("events", []))
            planning = result.cake.reference.geometric.planning
            for _, _, q_ms, ratio in planning.queries if planning else ():
                ms.append(q_ms)
                if ratio is not None:
                    ratios.append(ratio)
        walls[planner] = wall
        rel = np.median(np.array(wall) / np.array(walls["straight"]))
        med = f"{np.median(ms):.1f}" if ms else "-"
        p90 = f"{np.percentile(ms, 90):.1f}" if ms else "-"
        ratio = f"{np.median(ratios):.2f}" if ratios else "-"
        print(
            f"{planner:<13}{f'{built}/{len(problems)}':>7}{hits:>12}{disagreements:>15}"
            f"{len(ms):>9}{med:>11}{p90:>8}{ratio:>11}{rel:>17.2f}x"
        )

    _, queries = blocked_queries(args.queries)
    print(f"(b) {len(queries)} blocked moves between crowded towers")
    print(f"{'planner':<16}{'solved':>8}{'median ms':>11}{'p90 ms':>8}{'path/line':>11}")
    for spec in ("rrt-connect", "examples.via_point_planner:make"):
        planner = make_planner(spec)
        ms, ratios = [], []
        for q in queries:
            t0 = time.perf_counter()
            path = ask(planner, spec, q)
            ms.append((time.perf_counter() - t0) * 1000)
            if not isinstance(path, str):
                length = np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1))
                ratios.append(length / np.linalg.norm(q.goal - q.start))
        name = spec.split(".")[-1].split(":")[0]
        print(
            f"{name:<16}{f'{len(ratios)}/{len(queries)}':>8}{np.median(ms):>11.1f}"
            f"{np.percentile(ms, 90):>8.1f}{np.median(ratios):>11.2f}"
        )


if __name__ == "__main__":
    main()
