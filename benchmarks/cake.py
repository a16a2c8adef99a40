"""The cake in every combination: each layer classical or learned, on the same episodes.

Rows: symbolic {the planner (auto), the learned planner} x geometric {waypoints and IK,
the learned skills} x dynamic {computed torque, computed torque + the learned residual},
eight in all, plus a whole-task policy's row when ``--whole-task CHECKPOINT`` names one
(it replaces the top and middle together). Two sets of held-out episodes:

- ``problem_5``: the exercise's problem with its towers placed at random per seed
  (``learned_cake`` in models/scenarios/learning.yaml: 0.5 kg cubes, the residual's
  world); all eight rows;
- ``problem_5_light``: the same episodes with the default cubes (0.05 kg, the skills'
  demonstrations' world), the four symbolic x geometric rows under computed torque;
- ``generated6``: generated six-cube problems in the default world, the four symbolic x
  geometric rows under computed torque.

Seeds: as benchmarks/skills.py's, the development seeds 100000 and up (``--dev``: where
the skills' rules were tuned, and docs/learning.md's figures) and the test seeds 700000
and up (the default, never read while tuning).

Each episode is a whole run (planning, the execution monitor with ``re_place``, the
simulation, the verdict measured from the world), spread over ``--workers`` processes.
Prints one Markdown table per set (success with its 95 % Wilson interval, mean
simulated and wall time of the episodes, the failures by their first words) and, with
``--figure PNG``, draws the success rates with their intervals.

    python benchmarks/cake.py                      # 50 episodes a row (about an hour)
    python benchmarks/cake.py --episodes 4 --sets problem_5   # a quick look
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from machine import machine

ROOT = Path(__file__).resolve().parent.parent
SUITE = ROOT / "models" / "scenarios" / "learning.yaml"
SKILLS = "package://cake_drake/policies/skills"
RESIDUAL = "package://cake_drake/residuals/cubes_0.5kg"
DEV_SEED, TEST_SEED = 100000, 700000
SETS = ("problem_5", "problem_5_light", "generated6")


@dataclass(frozen=True)
class Row:
    symbolic: str  # "classical" | "learned"
    geometric: str
    dynamic: str
    whole_task: str = ""  # a checkpoint: replaces symbolic and geometric

    @property
    def label(self) -> str:
        if self.whole_task:
            return f"whole-task policy ({Path(self.whole_task).name}) / {self.dynamic}"
        return f"{self.symbolic} / {self.geometric} / {self.dynamic}"


def rows_for(set_name: str, whole_task: str | None) -> list[Row]:
    kinds = ("classical", "learned")
    dyn = kinds if set_name == "problem_5" else ("classical",)
    rows = [Row(s, g, d) for s in kinds for g in kinds for d in dyn]
    if whole_task and set_name == "problem_5":
        rows += [Row("learned", "learned", d, whole_task) for d in kinds]
    return rows


def scenario_for(set_name: str, row: Row, seed: int):
    """The episode's scenario: the set's problem and world, each layer as ``row`` says."""
    from cake_drake.scenario import ComputedTorque, Generate, Planned, Policy, load_scenario
    from cake_drake.world.scene import WorldConfig

    s = load_scenario(SUITE, "learned_cake")
    s.seed = seed
    s.outputs.render = False
    if set_name != "problem_5":  # the default cubes
        s.world.cube_mass_kg = WorldConfig().cube_mass_kg
    if set_name == "generated6":
        s.task.generate = Generate(blocks=6, seed=seed)
        s.world.placement.xy = s.world.placement.yaw_deg = 0.0
    s.task.planner = "learned" if row.symbolic == "learned" else "auto"
    s.motion.skills = SKILLS if row.geometric == "learned" else ""
    s.controller = ComputedTorque(
        kp=[100.0], kd=[20.0], residual=RESIDUAL if row.dynamic == "learned" else ""
    )
    if row.whole_task:
        s.reference = Policy(checkpoint=row.whole_task, action_space="joint_position",
                             rate_hz=10.0, max_steps=1000)  # fmt: skip
        s.motion.skills = ""
    else:
        s.reference = Planned(re_place=True)
    return s


def episode(job) -> dict:
    """One whole run (in a worker): its row of the table."""
    set_name, k, row, seed = job
    from cake_drake.errors import CakeDrakeError
    from cake_drake.pipeline import run

    t0 = time.perf_counter()
    try:
        result = run(scenario_for(set_name, row, seed), write=False)
        ok, message = result.success, result.message
        sim_s = result.execution.sim_s
    except CakeDrakeError as e:
        ok, message, sim_s = False, str(e), 0.0
    return {"set": set_name, "row": k, "seed": seed, "success": ok, "message": message,
            "sim_s": sim_s, "wall_s": time.perf_counter() - t0}  # fmt: skip


def why(message: str) -> str:
    """A failure's kind: its message's first clause, without the names of cubes."""
    import re

    first = message.split(" — ")[0].split("; ")[0]
    first = re.sub(r"'[^']*'", "'…'", first)
    first = re.sub(r"\([a-z-]+( [a-z0-9]+)+\)", "(action)", first)
    return first[:90]


def main(argv=None) -> int:
    from cake_drake.learning.evaluation import wilson
    from cake_drake.learning.parallel import imap

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--episodes", type=int, default=50, help="episodes a row (default 50)")
    ap.add_argument("--sets", nargs="+", default=list(SETS), choices=SETS)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--whole-task", metavar="CHECKPOINT",
                    help="a whole-task policy for problem_5 (e.g. trained on tower5)")  # fmt: skip
    ap.add_argument("--figure", type=Path, help="draw the success rates to this PNG")
    ap.add_argument("--save", type=Path, metavar="JSON",
                    help="keep each set's table here (a set run again replaces its own); "
                    "the figure draws every set the file holds")  # fmt: skip
    ap.add_argument("--dev", action="store_true", help="the development seeds, 100000 and up")
    args = ap.parse_args(argv)
    print(machine())
    first = DEV_SEED if args.dev else TEST_SEED
    seeds = list(range(first, first + args.episodes))
    tables = {}
    for set_name in args.sets:
        rows = rows_for(set_name, args.whole_task)
        jobs = [(set_name, k, row, s) for k, row in enumerate(rows) for s in seeds]
        t0 = time.perf_counter()
        done = list(imap(episode, jobs, args.workers))
        print(f"\n### {set_name}: {args.episodes} episodes a row (seeds {seeds[0]}-{seeds[-1]}), "
              f"{(time.perf_counter() - t0) / 60:.1f} min on {args.workers} workers\n")  # fmt: skip
        print("| symbolic / geometric / dynamic | success | 95 % interval | sim s | wall s | "
              "failures |")  # fmt: skip
        print("|---|---|---|---|---|---|")
        table = []
        for k, row in enumerate(rows):
            mine = [d for d in done if d["row"] == k]
            wins = sum(d["success"] for d in mine)
            lo, hi = wilson(wins, len(mine))
            sim = sum(d["sim_s"] for d in mine) / len(mine)
            wall = sum(d["wall_s"] for d in mine) / len(mine)
            fails = Counter(why(d["message"]) for d in mine if not d["success"])
            said = "; ".join(f"{n}× {w}" for w, n in fails.most_common(3)) or "-"
            print(f"| {row.label} | {wins}/{len(mine)} | {100 * lo:.0f}-{100 * hi:.0f} % | "
                  f"{sim:.1f} | {wall:.1f} | {said} |", flush=True)  # fmt: skip
            table.append((row.label, wins, len(mine), lo, hi))
        tables[set_name] = table
    if args.save:
        import json

        kept = json.loads(args.save.read_text()) if args.save.is_file() else {}
        kept.update(tables)
        args.save.write_text(json.dumps(kept, indent=1) + "\n")
        tables = {k: kept[k] for k in SETS if k in kept}
    if args.figure:
        draw(tables, args.figure)
        print(f"\nfigure: {args.figure}")
    return 0


def draw(tables: dict, path: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 1.2 + 0.42 * sum(len(t) for t in tables.values())), dpi=100)
    ax = fig.add_subplot(1, 1, 1)
    labels, y = [], 0
    colours = {"problem_5": "#355f9c", "problem_5_light": "#5a9c35", "generated6": "#9c7434"}
    for set_name, table in tables.items():
        for label, wins, n, lo, hi in table:
            rate = wins / n
            ax.errorbar(rate, y, xerr=[[rate - lo], [hi - rate]], fmt="o", capsize=3,
                        color=colours[set_name])  # fmt: skip
            labels.append(f"{set_name}: {label}")
            y += 1
    ax.set_yticks(range(len(labels)), labels, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlim(-0.02, 1.02)
    ax.set_xlabel("success (95 % Wilson interval); each row: symbolic / geometric / dynamic")
    ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)


if __name__ == "__main__":
    sys.exit(main())
