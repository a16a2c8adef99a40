"""The learned middle at every height and load: learned skills under the planner, row by row,
with the classical geometric layer on the same episodes beside each (the skills: the ones
that never see the arm, ``models/policies/skills_relative``, unless ``--skills`` names
another folder, such as the joint-space ``package://cake_drake/policies/skills``).

Rows (whole runs: planning, the execution monitor with ``re_place``, the simulation, the
verdict measured from the world), seeds 100000 and up, none a demonstration had:

- ``problem_5``: the exercise's problem, its towers placed at random per seed
  (``learned_tower5`` in models/scenarios/learning.yaml);
- ``generated N``: generated problems of N cubes (``--sizes``, default 6 8 10);
- ``tall N``: generated problems of N cubes in few, tall towers, start and goal
  (``--tall``, default 8 10);
- ``learned_cake``: every layer learned (the learned planner, the skills, the residual
  under computed torque), 0.5 kg cubes.

Prints one Markdown table: success with its 95 % Wilson interval, how far each stacked
cube was set off the one below (median / 95th percentile, mm), the mean simulated time,
and the failures by their first words; ``--json`` keeps the rows.

    python benchmarks/skills.py                          # 50 episodes a row (hours)
    python benchmarks/skills.py --episodes 10 --rows problem_5 tall8   # a quick look
    python benchmarks/skills.py --skills package://cake_drake/policies/skills --no-classical
"""

from __future__ import annotations

import argparse
import json
import re
import time
from collections import Counter
from pathlib import Path

import numpy as np
from cake import why  # a failure's kind, as the cake's table says it
from machine import machine

ROOT = Path(__file__).resolve().parent.parent
SUITE = ROOT / "models" / "scenarios" / "learning.yaml"
SKILLS = "package://cake_drake/policies/skills_relative"
FIRST_SEED = 100000


def rows_named(sizes, tall) -> list[str]:
    return ["problem_5", *[f"generated{n}" for n in sizes], *[f"tall{n}" for n in tall],
            "learned_cake"]  # fmt: skip


def scenario_for(row: str, skills: str, seed: int):
    """The episode's scenario: ``row``'s problem and world, ``skills`` as the geometric
    layer (empty: the classical one)."""
    from cake_drake.scenario import Generate, load_scenario

    s = load_scenario(SUITE, "learned_cake" if row == "learned_cake" else "learned_tower5")
    s.seed = seed
    s.outputs.render = False
    match = re.fullmatch(r"(generated|tall)(\d+)", row)
    if match:
        s.task.generate = Generate(blocks=int(match[2]), seed=seed, tall=match[1] == "tall")
        s.task.problem = ""
        s.world.placement.xy = s.world.placement.yaw_deg = 0.0
    s.motion.skills = skills
    return s


def episode(job) -> dict:
    """One whole run (in a worker): its row of the table."""
    row, column, skills, seed = job
    from cake_drake.errors import CakeDrakeError
    from cake_drake.pipeline import run

    t0 = time.perf_counter()
    places: list[float] = []
    try:
        result = run(scenario_for(row, skills, seed), write=False)
        ok, message, sim_s = result.success, result.message, result.execution.sim_s
        places = [p["offset_mm"] for p in result.execution.monitoring.get("places", [])]
    except CakeDrakeError as e:
        ok, message, sim_s = False, str(e), 0.0
    return {"row": row, "column": column, "seed": seed, "success": ok, "message": message,
            "sim_s": sim_s, "places_mm": places, "wall_s": time.perf_counter() - t0}  # fmt: skip


def main(argv=None) -> int:
    from cake_drake.learning.evaluation import wilson
    from cake_drake.learning.parallel import imap

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--episodes", type=int, default=50, help="episodes a row (default 50)")
    ap.add_argument("--sizes", type=int, nargs="*", default=[6, 8, 10])
    ap.add_argument("--tall", type=int, nargs="*", default=[8, 10])
    ap.add_argument("--rows", nargs="+", help="only these rows (e.g. problem_5 tall8)")
    ap.add_argument("--skills", default=SKILLS, help="the skills' folder")
    ap.add_argument("--no-classical", action="store_true", help="skip the classical column")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", type=Path, help="also write every episode's row here")
    args = ap.parse_args(argv)
    print(machine())
    rows = args.rows or rows_named(args.sizes, args.tall)
    columns = [("learned skills", args.skills)] + ([] if args.no_classical else
                                                   [("classical", "")])  # fmt: skip
    seeds = range(FIRST_SEED, FIRST_SEED + args.episodes)
    jobs = [(row, name, path, s) for row in rows for name, path in columns for s in seeds]
    t0 = time.perf_counter()
    done = list(imap(episode, jobs, args.workers))
    print(f"\n{args.episodes} episodes a row (seeds {seeds[0]}-{seeds[-1]}), skills "
          f"{args.skills}, {(time.perf_counter() - t0) / 60:.1f} min on {args.workers} "
          "workers\n")  # fmt: skip
    print("| row | geometric layer | success | 95 % interval | places mm (median / p95) "
          "| sim s | failures |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for row in rows:
        for name, _ in columns:
            mine = [d for d in done if d["row"] == row and d["column"] == name]
            wins = sum(d["success"] for d in mine)
            lo, hi = wilson(wins, len(mine))
            places = [p for d in mine for p in d["places_mm"]]
            said_places = (f"{np.median(places):.1f} / {np.percentile(places, 95):.1f}"
                           if places else "-")  # fmt: skip
            sim = np.mean([d["sim_s"] for d in mine if d["success"]] or [float("nan")])
            fails = Counter(why(d["message"]) for d in mine if not d["success"])
            said = "; ".join(f"{n}× {w}" for w, n in fails.most_common(2)) or "-"
            print(f"| {row} | {name} | {wins}/{len(mine)} | {100 * lo:.0f}-{100 * hi:.0f} % "
                  f"| {said_places} | {sim:.1f} | {said} |", flush=True)  # fmt: skip
    if args.json:
        args.json.write_text(json.dumps(done, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
