"""The Blocksworld suite end to end: n = 3..12 blocks, every seed, one table row each.

    python benchmarks/suite.py [--sizes 3 12] [--seeds 3] [--mode torque|position]
                               [--time-limit S] [--jobs 1] [--json FILE] [--skills FOLDER]
                               [--perception depth|depth+noise]

The problems are :func:`cake_drake.symbolic.blocksworld.suite_problems`: per size, seed
0 is random towers to random towers in the exercise's naming with a complete goal, seed
1 the IPC naming with tall towers (start up to 10 high) and a partial goal, seed 2 the
typed naming with towers capped at 10 and 9 and a partial goal (further seeds cycle).
Each one runs through ``cake_drake.pipeline.run(scenario, write=False)`` - plan with
``auto``, build the Diagram, simulate, read the verdict from the measured poses - in a
fresh Python process of its own, so that one problem's memory, caches or crash cannot
touch the next, and ``wall s`` is what a user waits for (interpreter start and imports
included). Rows print as problems finish; then the success rate, overall and per size.
``--jobs 2`` runs two at a time (only on an otherwise idle machine: the wall times then
compete for the cores).

``--skills FOLDER`` runs the same problems with learned skills as the geometric layer
(``motion.skills``, e.g. ``package://cake_drake/policies/skills``) under the same
planner, the monitor setting a stacked cube down again when it stands off the one below
(``re_place``, as the shipped ``learned_tower5``). ``--perception depth`` (or
``depth+noise``) runs them with the cake reading the cubes from the cameras
(docs/perception.md).

Columns: blocks, seed, naming, planner (the one that answered), plan length, planning
s, simulated s, wall s (whole process), success, largest xy offset of a stacked cube
from the one below (mm), and why a run failed.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from machine import machine  # benchmarks/machine.py

COLUMNS = (
    "n", "seed", "naming", "planner", "plan", "planning s", "simulated s", "wall s",
    "success", "largest offset mm",
)  # fmt: skip


def run_one(
    name: str, mode: str, time_limit: float | None, skills: str = "", perception: str = ""
) -> dict:
    """Run one suite problem in this process and return its row (the worker's job)."""
    from cake_drake.pipeline import run
    from cake_drake.scenario import Planned, Scenario, controller_for_mode
    from cake_drake.symbolic.blocksworld import suite_problems

    problems = {p[0]: p for p in suite_problems(range(1, 64), range(0, 64))}
    _, naming, text = problems[name]
    with tempfile.TemporaryDirectory() as tmp:
        problem = Path(tmp) / f"{name}.pddl"
        problem.write_text(text)
        s = Scenario(controller=controller_for_mode(mode))
        s.task.domain = str(naming.domain_file)
        s.task.problem = str(problem)
        s.task.time_limit = time_limit
        if skills:
            s.motion.skills = skills
            s.reference = Planned(re_place=True)
        if perception:  # "depth" or "depth+noise": from the cameras (docs/perception.md)
            s.perception.estimator = perception.split("+")[0]
            s.perception.noise.model = "axial" if perception.endswith("+noise") else "off"
        result = run(s, write=False)
    execution = result.execution
    return {
        "planner": result.plan.planner,
        "plan": result.plan.length,
        "planning_s": result.stages.get("planning", 0.0),
        "sim_s": execution.sim_s,
        "success": result.success,
        "offset_mm": 1000 * max(execution.offsets.values(), default=0.0),
        "message": "" if result.success else result.message,
    }


def spawn(
    name: str, mode: str, time_limit: float | None, skills: str = "", perception: str = ""
) -> dict:
    """One problem in a fresh process; its row, with the whole process's wall time."""
    cmd = [sys.executable, __file__, "--one", name, "--mode", mode]
    if perception:
        cmd += ["--perception", perception]
    if time_limit is not None:
        cmd += ["--time-limit", str(time_limit)]
    if skills:
        cmd += ["--skills", skills]
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    lines = r.stdout.strip().splitlines()
    if r.returncode == 0 and lines:
        row = json.loads(lines[-1])
    else:  # the run itself refused or crashed: a failure, with its last line
        last = (r.stderr.strip().splitlines() or ["no output"])[-1]
        row = {"planner": "-", "plan": 0, "planning_s": 0.0, "sim_s": 0.0, "success": False,
               "offset_mm": 0.0, "message": f"exit {r.returncode}: {last}"}  # fmt: skip
    row["wall_s"] = wall
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs=2, default=(3, 12), metavar=("MIN", "MAX"))
    parser.add_argument("--seeds", type=int, default=3, help="seeds per size (default 3)")
    parser.add_argument("--mode", choices=("torque", "position"), default="torque")
    parser.add_argument("--time-limit", type=float, default=None, help="planner limit, s")
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--json", type=Path, help="also write the rows here")
    parser.add_argument("--skills", default="", help="learned skills' folder (default: classical)")
    parser.add_argument(
        "--perception", default="", help="depth | depth+noise: the cubes from the cameras"
    )
    parser.add_argument("--one", help=argparse.SUPPRESS)  # worker: run one problem
    args = parser.parse_args()
    if args.one:
        row = run_one(args.one, args.mode, args.time_limit, args.skills, args.perception)
        print(json.dumps(row))
        return

    from cake_drake.symbolic.blocksworld import suite_problems

    lo, hi = args.sizes
    problems = suite_problems(range(lo, hi + 1), range(args.seeds))
    print(machine())
    layer = f"skills {args.skills}" if args.skills else "classical geometric layer"
    seen = f", perception {args.perception}" if args.perception else ""
    print(f"mode {args.mode}, planner auto, {layer}{seen}, {len(problems)} problems, one "
          "process each")  # fmt: skip
    print(" | ".join(COLUMNS))
    print(" | ".join("---" for _ in COLUMNS))
    rows = []

    def job(p):
        name, naming, _ = p
        n, seed = (int(x) for x in name.rsplit("-", 2)[1:])
        row = spawn(name, args.mode, args.time_limit, args.skills, args.perception)
        return n, seed, naming.name, row

    with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        for n, seed, naming, row in pool.map(job, problems):
            row.update(n=n, seed=seed, naming=naming)
            rows.append(row)
            cells = [
                n, seed, naming, row["planner"], row["plan"], f"{row['planning_s']:.2f}",
                f"{row['sim_s']:.1f}", f"{row['wall_s']:.1f}",
                "yes" if row["success"] else "**no**", f"{row['offset_mm']:.1f}",
            ]  # fmt: skip
            line = " | ".join(str(c) for c in cells)
            if not row["success"]:
                line += f"  ({row['message'][:160]})"
            print(line, flush=True)
    ok = sum(r["success"] for r in rows)
    print(f"\nsuccess: {ok}/{len(rows)} ({100 * ok / max(1, len(rows)):.0f} %)")
    per = {}
    for r in rows:
        per.setdefault(r["n"], []).append(r["success"])
    print("per size: " + ", ".join(f"n={n} {sum(v)}/{len(v)}" for n, v in sorted(per.items())))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
