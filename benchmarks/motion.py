"""Motion-planner benchmark: the crowded table (slot radius 0.4 m, towers 10.4 cm apart)
under ``straight`` and ``rrt-connect``, on problem_5 and on seeded generated problems.

Per planner: towers built; collisions of the executed moves found by the run's own
collision report (SceneGraph penetration, every 0.02 rad of every move; a check
independent of the planner's checker); the monitor's disagreements with the plan (a
knocked cube shows as one); motion-planner queries (blocked moves), their time (median,
p90) and path length against the blocked straight line; the simulated run's wall time
against ``straight``.

    python benchmarks/motion.py [--seeds 10]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from machine import machine  # noqa: E402 - benchmarks/machine.py

from cake_drake.pipeline import run  # noqa: E402
from cake_drake.scenario import Generate, Scenario  # noqa: E402


def crowded(problem: Generate | None, planner: str) -> Scenario:
    s = Scenario()
    s.world.slot_radius = 0.4
    s.world.slot_spacing = s.world.slot_spacing_max = 0.104
    s.motion.planner = planner
    if problem is not None:
        s.task.generate = problem
    return s


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=10, help="generated problems per size")
    args = parser.parse_args()
    problems = [None] + [
        Generate(blocks=n, seed=k) for n in (4, 6, 8) for k in range(args.seeds // 3 + 1)
    ][: args.seeds]
    print(machine())
    print(f"crowded table, problem_5 and {len(problems) - 1} generated problems of 4 to 8 blocks")
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
            planning = result.cake.reference.waypoint_ik.planning
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


if __name__ == "__main__":
    main()
