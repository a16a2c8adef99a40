"""Whole-process wall time of `python -m cake_drake.run`, per mode, with a stage breakdown.

    python benchmarks/run.py [--repeats N] [--problem P]

Each run is a fresh process (interpreter start and imports included) writing every
output (plan, trajectory, final-state picture, joint-4 plot, summary). Medians over
the repeats; the stage times come from each run's summary.json.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from machine import machine  # benchmarks/machine.py

STAGES = ["import", "planning", "diagram_build", "simulation", "ik", "outputs"]


def one_run(mode: str, problem: str | None, extra: list[str]) -> dict:
    with tempfile.TemporaryDirectory() as out:
        cmd = [sys.executable, "-m", "cake_drake.run", "--mode", mode, "--out", out, "--quiet"]
        if problem:
            cmd += ["--problem", problem]
        t0 = time.perf_counter()
        r = subprocess.run(cmd + extra, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if r.returncode != 0:
            sys.exit(f"run failed ({r.returncode}): {r.stderr.strip()}")
        summary = json.loads((Path(out) / "summary.json").read_text())
    summary["process_s"] = wall
    return summary


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--problem", default=None)
    args = p.parse_args()
    print(f"machine: {machine()}")
    print(f"median of {args.repeats} runs per row; every run builds the tower (exit 0)\n")
    head = ["mode", "process s", "sim s", "RTF", *[f"{s} s" for s in STAGES], "max err mrad"]
    print(" | ".join(head))
    print(" | ".join("---" for _ in head))
    replay = None
    for mode, extra in [("position", []), ("torque", []), ("torque replay", None)]:
        if extra is None:  # replay the position run's trajectory, as exercise 4.x.3 does
            replay = tempfile.mkdtemp()
            subprocess.run(
                [
                    sys.executable,
                    "-m",
                    "cake_drake.run",
                    "--mode",
                    "position",
                    "--out",
                    replay,
                    "--quiet",
                    "--no-render",
                ],
                check=True,
                capture_output=True,
            )
            extra = ["--reference", str(Path(replay) / "trajectory.npz")]
        runs = [one_run(mode.split()[0], args.problem, extra) for _ in range(args.repeats)]

        def med(f, runs=runs):
            return statistics.median(f(r) for r in runs)

        cells = [
            mode,
            f"{med(lambda r: r['process_s']):.2f}",
            f"{med(lambda r: r['sim_s']):.1f}",
            f"{med(lambda r: r['rtf']):.1f}",
            *[f"{med(lambda r, s=s: r['stages_s'].get(s, 0.0)):.3f}" for s in STAGES],
            f"{med(lambda r: max(r['tracking_error']['max_rad'])) * 1000:.1f}",
        ]
        print(" | ".join(cells))


if __name__ == "__main__":
    main()
