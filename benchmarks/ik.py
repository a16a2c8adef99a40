"""IK benchmark: success rate, median and p90 solve time of both solvers on two sets.

(a) tabletop: every waypoint of problem_5 and of seeded generated problems (planned by
    gbfs-ff, whose longer plans give more waypoints), in plan order, each seeded with the
    solver's previous solution (as ``solve_action`` does), at the pipeline's tolerances.
    The cubes' poses are rolled forward symbolically: the picked cube rides in the hand,
    the placed cube rests where it was set down.
(b) random (the TRAC-IK protocol): random configurations uniformly within the joint
    limits -> forward kinematics -> solve that pose from the mid-limits seed. Success is
    checked independently (position within 1e-5 m, rotation within 1e-5 rad, joints
    within limits); both solvers are built with 1e-5 tolerances.

With ``--json`` the last line is one JSON object
``{"tabletop": {"drake": {"success_rate", "median_ms", "p90_ms"}, "dls": {...}},
"random": {...}}`` (``success_rate`` is a fraction, 0..1). Times are wall-clock per
``solve`` call, on one core. The text output also times the collision check
(:mod:`cake_drake.geometric.collisions`) on every move of the tabletop plans.
"""

from __future__ import annotations

import argparse
import json
import time
from collections import Counter

import numpy as np
from machine import machine  # benchmarks/machine.py
from pydrake.math import RigidTransform

from cake_drake.geometric.collisions import CollisionChecker, action_collisions
from cake_drake.geometric.ik import DlsIk, DrakeIk, Kinematics
from cake_drake.geometric.waypoints import (
    PICK_ACTIONS,
    Waypoint,
    WaypointParams,
    WorldView,
    waypoints_for,
)
from cake_drake.symbolic import (
    BLOCKSWORLD_DOMAIN,
    PROBLEM_5,
    GroundAction,
    load_domain,
    load_problem,
    parse_problem,
    random_problem,
    solve_problem,
    towers,
)
from cake_drake.world.scene import Q_HOME, layout

PROTOCOL_TOL = 1e-5  # m and rad, as TRAC-IK's published benchmark
#: Generated problems of the tabletop set: (blocks, seed).
GENERATED = ((5, 1), (6, 2), (6, 3), (7, 4))


def rollout(
    actions: list[GroundAction],
    init_poses: dict[str, RigidTransform],
    X_WG: RigidTransform,
    params: WaypointParams = WaypointParams(),
) -> list[tuple[GroundAction, WorldView, list[Waypoint]]]:
    """Each action with the world it should find and its waypoints, rolled forward."""
    poses = dict(init_poses)
    held, X_GB = None, RigidTransform()
    out = []
    for action in actions:
        world = WorldView(dict(poses), X_WG, held)
        wps = waypoints_for(action, world, params)
        out.append((action, world, wps))
        block = action.args[0]
        if action.name in PICK_ACTIONS:
            X_GB = wps[1].X_WG.inverse() @ poses[block]  # grasp: the cube in the hand
            poses[block] = wps[-1].X_WG @ X_GB  # lifted with the hand
            held = block
        else:
            X_WB = wps[1].X_WG @ X_GB  # where it is released ...
            p = X_WB.translation() - [0, 0, params.place_drop]  # ... and falls onto
            poses[block] = RigidTransform(X_WB.rotation(), p)
            held = None
        X_WG = wps[-1].X_WG
    return out


def tabletop_plans(kin: Kinematics) -> list[list[tuple[GroundAction, WorldView, list[Waypoint]]]]:
    """problem_5 and the generated problems, planned and rolled forward."""
    domain = load_domain(BLOCKSWORLD_DOMAIN)
    problems = [load_problem(BLOCKSWORLD_DOMAIN, PROBLEM_5)]
    problems += [parse_problem(domain, random_problem(n, s)) for n, s in GENERATED]
    plans = []
    for problem in problems:
        plan = solve_problem(problem, "gbfs-ff")
        start = layout(towers(problem.init))
        plans.append(rollout(list(plan.actions), start, kin.pose(Q_HOME)))
    return plans


def time_collision_checks(plans, kin: Kinematics) -> tuple[list[float], int, int]:
    """Per-move time of the collision check over every plan (DrakeIk solutions)."""
    ik = DrakeIk(kin)
    per_move, moves, found = [], 0, 0
    for steps in plans:
        checker = CollisionChecker(sorted(steps[0][1].cube_poses))
        q = Q_HOME.copy()
        for action, world, wps in steps:
            sols = []
            for w in wps:
                sols.append(ik.solve(w.X_WG, sols[-1] if sols else q))
            t0 = time.perf_counter()
            found += len(action_collisions(checker, action, world, wps, q, sols))
            per_move.append((time.perf_counter() - t0) / len(wps))
            moves += len(wps)
            q = sols[-1]
    return per_move, moves, found


def summary(times: list[float], ok: list[bool]) -> dict[str, float]:
    t = np.array(times) * 1e3
    return {
        "success_rate": float(np.mean(ok)),
        "median_ms": float(np.median(t)),
        "p90_ms": float(np.percentile(t, 90)),
        "mean_ms": float(np.mean(t)),  # printed, not in the JSON
    }


def run_tabletop(solver, kin: Kinematics, poses: list[RigidTransform]):
    """Solve the waypoints in order, each seeded with the previous solution."""
    times, ok, q = [], [], Q_HOME.copy()
    for X in poses:
        t0 = time.perf_counter()
        sol = solver.solve(X, q)
        times.append(time.perf_counter() - t0)
        good = sol is not None and kin.within(sol, X, solver.position_tol, solver.orientation_tol)
        ok.append(good)
        q = sol if good else q
    return summary(times, ok)


def run_random(solver, kin: Kinematics, n: int, seed: int, stages: Counter | None = None):
    rng = np.random.default_rng(seed)
    times, ok = [], []
    for _ in range(n):
        X = kin.pose(rng.uniform(kin.lower, kin.upper))
        t0 = time.perf_counter()
        sol = solver.solve(X, kin.mid)
        times.append(time.perf_counter() - t0)
        if sol is None:
            ok.append(False)
        else:
            dp, dr = kin.pose_errors(sol, X)
            ok.append(dp <= PROTOCOL_TOL and dr <= PROTOCOL_TOL and kin.within_limits(sol))
        if stages is not None:
            stages[solver.last.stage] += 1
    return summary(times, ok)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--samples", type=int, default=1000, help="random poses (default 1000)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random poses")
    parser.add_argument("--json", action="store_true", help="end with one line of JSON")
    args = parser.parse_args(argv)
    if args.samples < 1:
        parser.error(f"--samples must be a positive integer, got {args.samples}")

    kin = Kinematics()
    print(f"machine: {machine()}")
    results: dict[str, dict[str, dict[str, float]]] = {"tabletop": {}, "random": {}}
    plans = tabletop_plans(kin)
    poses = [w.X_WG for steps in plans for _, _, wps in steps for w in wps]
    t0 = time.perf_counter()
    for name, solver in (("drake", DrakeIk(kin)), ("dls", DlsIk(kin))):
        results["tabletop"][name] = run_tabletop(solver, kin, poses)
    tab_s = time.perf_counter() - t0
    stages: Counter = Counter()
    tols = {"position_tol": PROTOCOL_TOL, "orientation_tol": PROTOCOL_TOL}
    t0 = time.perf_counter()
    drake = DrakeIk(kin, **tols)
    drake.table  # noqa: B018 - build the seed table outside the timed solves
    results["random"]["drake"] = run_random(drake, kin, args.samples, args.seed, stages)
    results["random"]["dls"] = run_random(DlsIk(kin, **tols), kin, args.samples, args.seed)
    rand_s = time.perf_counter() - t0

    print(f"(a) tabletop: {len(poses)} waypoints of problem_5 and {len(GENERATED)} generated "
          f"problems, tolerances 1e-4 m / 1e-3 rad ({tab_s:.1f} s)")  # fmt: skip
    print(f"(b) random: {args.samples} configurations (seed {args.seed}) from the mid-limits "
          f"seed, checked at 1e-5 m / 1e-5 rad ({rand_s:.1f} s)")  # fmt: skip
    print(f"{'set':<10}{'solver':<8}{'success':>10}{'median ms':>11}{'p90 ms':>9}{'mean ms':>9}")
    for set_name, by_solver in results.items():
        for name, r in by_solver.items():
            print(f"{set_name:<10}{name:<8}{100 * r['success_rate']:>9.2f}%"
                  f"{r['median_ms']:>11.3f}{r['p90_ms']:>9.3f}{r['mean_ms']:>9.3f}")  # fmt: skip
    print("drake stages on (b): " + ", ".join(f"{k} {v}" for k, v in sorted(stages.items())))
    per_move, moves, found = time_collision_checks(plans, kin)
    print(f"collision check of the tabletop moves: {moves} moves, {found} collisions, "
          f"median {1e3 * np.median(per_move):.2f} ms / move, "
          f"max {1e3 * np.max(per_move):.2f} ms / move (mean over an action)")  # fmt: skip
    if args.json:
        keys = ("success_rate", "median_ms", "p90_ms")
        print(json.dumps({set_name: {name: {k: r[k] for k in keys} for name, r in by.items()}
                          for set_name, by in results.items()}))  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
