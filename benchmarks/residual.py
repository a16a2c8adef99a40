"""The learned bottom (§4.4): 0.5 kg cubes the controller's model does not know, under
computed torque, with no correction, integral action, the learned residual and the true
model, side by side on held-out problems.

1. Training: problem_5 and a generated four-cube problem run under computed torque
   (Kp 100, Kd 20) with 0.5 kg cubes and ``outputs.logs``, uncorrected (the labels do
   not depend on the controller); ``train --residual`` fits the residual to their logs.
2. Held out: other problems (three, four and six cubes; ``models/pddl/tower3.pddl``),
   at Kd 20 and Kd 5, each run four ways: ``none``, ``ki`` (integral action, Ki 200, the
   gains study's), ``learned`` (the residual) and ``true`` (the residual of a 0.5 kg
   held mass, known exactly: the floor).

Prints one row per controller and Kd (over the held-out problems): the peak and RMS joint
error while carrying (elbow, joint 4; wrist, joint 6), the peak error in the first second
after each grasp, the settling after each place (the largest joint error 0.3 s after
each release), the
goals reached and the simulation's wall time. Writes ``residual_comparison.png`` (one
panel per row: the wrist's error on one held-out problem, phases shaded) and, with
``--ship DIR``, the learned residual.

    python benchmarks/residual.py --out outputs/residual_study
"""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path

import numpy as np
from machine import machine

from cake_drake.dynamic.residual import HOLD, from_mass
from cake_drake.formats import PHASE_NAMES
from cake_drake.learning.training.residual import describe, train_residual
from cake_drake.pipeline import run
from cake_drake.scenario import ComputedTorque, Generate, Scenario

ROOT = Path(__file__).resolve().parents[1]

MASS = 0.5
KI = 200.0
ELBOW, WRIST = 3, 5  # joints 4 and 6
CARRYING = {PHASE_NAMES.index("lift"), PHASE_NAMES.index("transport")}
TRAIN = [("problem_5", None)] + [
    (f"generated, {n} cubes, seed {seed}", Generate(blocks=n, seed=seed))
    for n, seed in ((4, 1), (3, 2), (5, 3), (6, 4))
]
HELD_OUT = [
    ("generated, 3 cubes, seed 11", Generate(blocks=3, seed=11)),
    ("generated, 4 cubes, seed 12", Generate(blocks=4, seed=12)),
    ("generated, 6 cubes, seed 13", Generate(blocks=6, seed=13)),
    ("tower3.pddl", str(ROOT / "models" / "pddl" / "tower3.pddl")),
]
ROWS = ("none", "ki", "learned", "true")
LABELS = {"none": "no correction", "ki": f"integral action (Ki {KI:g})",
          "learned": "learned residual", "true": "true model"}  # fmt: skip


def scenario(problem, kd: float, row: str, residual: Path | None, out: Path | None) -> Scenario:
    s = Scenario()
    if isinstance(problem, Generate):
        s.task.generate = problem
    elif problem is not None:
        s.task.problem = problem
    s.world.cube_mass_kg = MASS
    s.controller = ComputedTorque(kp=[100.0], kd=[kd], ki=[KI if row == "ki" else 0.0])
    if row in ("learned", "true"):
        s.controller.residual = str(residual)
    s.outputs.render = False
    if out is not None:
        s.outputs.folder, s.outputs.logs = str(out), True
    return s


def metrics(result) -> dict:
    logs = result.execution.logs
    t, e = logs.t, np.abs(logs.q_d - logs.q)
    held = (logs.fingers >= HOLD[0]) & (logs.fingers <= HOLD[1])
    carrying = held & np.isin(logs.phase, list(CARRYING))
    lift = PHASE_NAMES.index("lift")
    starts = np.flatnonzero((logs.phase[1:] == lift) & (logs.phase[:-1] != lift)) + 1
    first = [e[(t >= t[i]) & (t < t[i] + 1.0)].max() for i in starts]
    place, retract = PHASE_NAMES.index("place"), PHASE_NAMES.index("retract")
    ends = np.flatnonzero((logs.phase[1:] == retract) & (logs.phase[:-1] == place)) + 1
    # Settling: the largest joint error 0.3 s after each release (the place's end).
    settle = [e[min(np.searchsorted(t, t[i] + 0.3), len(t) - 1)].max() for i in ends]
    pick = e[carrying] if carrying.any() else np.zeros((1, 7))
    return {
        "peak": pick[:, [ELBOW, WRIST]].max(axis=0),
        "rms": np.sqrt((pick[:, [ELBOW, WRIST]] ** 2).mean(axis=0)),
        "first_s": max(first) if first else float("nan"),
        "settle": max(settle) if settle else float("nan"),
        "success": result.success,
        "wall": result.execution.wall_s,
        "t": t,
        "e_wrist": (logs.q_d - logs.q)[:, WRIST],
        "phase": logs.phase,
    }


def plot(curves: dict, title: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cake_drake.outputs.plots import phase_key, phase_spans, shade_phases

    fig, axes = plt.subplots(len(curves), 1, figsize=(9, 1.9 * len(curves) + 0.8), sharex=True)
    span = max(np.abs(m["e_wrist"]).max() for m in curves.values()) * 1e3 * 1.1
    for ax, (label, m) in zip(axes, curves.items(), strict=True):
        shade_phases(ax, phase_spans(m["t"], m["phase"]))
        ax.plot(m["t"], m["e_wrist"] * 1e3, color="black", lw=0.9)
        ax.set_ylim(-span, span)
        ax.set_ylabel("mrad")
        verdict = "goal reached" if m["success"] else "failed"
        ax.set_title(f"{label}: wrist error peak {m['peak'][1] * 1e3:.1f} mrad carrying; {verdict}",
                     fontsize=9, loc="left")  # fmt: skip
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(title, fontsize=10, y=0.995)
    phase_key(fig)
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=ROOT / "outputs" / "residual_study")
    p.add_argument("--ship", type=Path, help="copy the learned residual here")
    p.add_argument("--plot", type=Path, help="where residual_comparison.png goes (default OUT)")
    args = p.parse_args()
    print(machine())
    out = args.out
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    runs = []
    for k, (name, problem) in enumerate(TRAIN):
        result = run(scenario(problem, 20.0, "none", None, out / f"train{k}"))
        runs.append(out / f"train{k}")
        print(f"training run {name}: {result.message.splitlines()[0][:90]}")
    learned = out / "learned"
    train_residual(runs, learned)
    print(describe(learned))
    true = out / "true"
    from_mass(MASS).save(true)
    residual = {"learned": learned, "true": true}
    table = {}
    curves = {}
    for kd in (20.0, 5.0):
        for row in ROWS:
            got = []
            for name, problem in HELD_OUT:
                result = run(scenario(problem, kd, row, residual.get(row), None), write=False)
                got.append(metrics(result))
                if kd == 20.0 and name == HELD_OUT[1][0]:
                    curves[LABELS[row]] = got[-1]
            table[kd, row] = got
    print(f"\n{len(HELD_OUT)} held-out problems, 0.5 kg cubes, computed torque Kp 100; "
          "errors in mrad (worst problem), wall in s (median)")  # fmt: skip
    print(
        f"{'Kd':>3} {'correction':<10} {'peak elbow':>10} {'peak wrist':>10} "
        f"{'rms elbow':>9} {'rms wrist':>9} {'1st s':>6} {'settle':>6} {'goals':>6} {'wall':>5}"
    )
    for (kd, row), got in table.items():
        peak = np.max([g["peak"] for g in got], axis=0) * 1e3
        rms = np.max([g["rms"] for g in got], axis=0) * 1e3
        first = max(g["first_s"] for g in got) * 1e3
        settle = max(g["settle"] for g in got) * 1e3
        goals = sum(g["success"] for g in got)
        wall = np.median([g["wall"] for g in got])
        print(
            f"{kd:>3g} {row:<10} {peak[0]:>10.1f} {peak[1]:>10.1f} {rms[0]:>9.1f} "
            f"{rms[1]:>9.1f} {first:>6.1f} {settle:>6.1f} {goals:>3}/{len(got)} {wall:>5.2f}"
        )
    path = (args.plot or out) / "residual_comparison.png"
    plot(curves, f"{HELD_OUT[1][0]} (held out), 0.5 kg cubes, Kp 100 Kd 20: joint 6 (wrist) error",
         path)  # fmt: skip
    print(f"\nplot: {path}")
    if args.ship:  # residual.json replaced, the folder's README kept
        args.ship.mkdir(parents=True, exist_ok=True)
        shutil.copy(learned / "residual.json", args.ship / "residual.json")
        print(f"shipped: {args.ship / 'residual.json'}")


if __name__ == "__main__":
    t0 = time.perf_counter()
    main()
    print(f"{time.perf_counter() - t0:.0f} s in all")
