"""Whole-process wall time of `python -m cake_drake.run`, per mode (and the torque run from
the cameras), with a stage breakdown, then the same runs side by side with the two peers.

    python benchmarks/run.py [--repeats N] [--problem P] [--rounds R] [--peers DIR] [--busy]

Where LeRobot is installed, the learned layers' shipped runs follow (learning.yaml's
``learned_stack2``: the state policy in the slot; ``learned_tower5``: learned skills
under the planner), measured the same way. Each run is a fresh process (interpreter
start and imports included) writing every output (plan, trajectory, final-state
picture, joint-4 plot, summary). Medians over
the repeats; the stage times come from each run's summary.json; CPU is user + system
time of the run and its helpers, peak memory the largest single process of the run.

With the peers' folder present (default ../shared/peers beside the project), its
compare.py then times cake_drake against the PyBullet version and the tuned Drake
script in one paired run (A B C, A B C, ...) and prints the ratios.

``--busy`` measures everything with a second job on the machine: a position-mode run of
cake_drake in a loop, started before the first measurement and stopped after the last,
so that every command, the peers' too, shares the cores with it.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from machine import machine  # benchmarks/machine.py

ROOT = Path(__file__).resolve().parent.parent

#: Runs one command and prints its wall time, the CPU time of it and its helpers (every
#: descendant is waited for) and the largest of those processes' peak memory.
MEASURE = """
import json, resource, subprocess, sys, time
t0 = time.perf_counter()
code = subprocess.run(json.loads(sys.argv[1]), stdout=subprocess.DEVNULL).returncode
wall = time.perf_counter() - t0
u = resource.getrusage(resource.RUSAGE_CHILDREN)
print(json.dumps({"process_s": wall, "cpu_s": u.ru_utime + u.ru_stime,
                  "peak_mib": u.ru_maxrss / 1024}))
sys.exit(code)
"""

STAGES = ["import", "planning", "diagram_build", "simulation", "ik", "outputs"]
LEARNING = ROOT / "models" / "scenarios" / "learning.yaml"
#: The shipped learned runs measured beside the classical ones (their scenarios' names).
LEARNED = ("learned_stack2", "learned_tower5")


def one_run(run_args: list[str], problem: str | None, extra: list[str]) -> dict:
    with tempfile.TemporaryDirectory() as out:
        cmd = [sys.executable, "-m", "cake_drake.run", *run_args, "--out", out, "--quiet"]
        if problem:
            cmd += ["--problem", problem]
        r = subprocess.run(
            [sys.executable, "-c", MEASURE, json.dumps(cmd + extra)], capture_output=True, text=True
        )
        if r.returncode != 0:
            sys.exit(f"run failed ({r.returncode}): {r.stderr.strip()}")
        figures = json.loads(r.stdout.strip().splitlines()[-1])
        summary = json.loads((Path(out) / "summary.json").read_text())
    summary.update(figures)
    return summary


@contextlib.contextmanager
def second_job(on: bool):
    """A cake_drake run in a loop, in its own process group, while the block runs."""
    if not on:
        yield
        return
    run = [sys.executable, "-m", "cake_drake.run", "--mode", "position", "--quiet"]
    run += ["--out", tempfile.mkdtemp()]
    forever = (
        "import subprocess, sys\n"
        "while True:\n"
        "    subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)\n"
    )
    loop = subprocess.Popen([sys.executable, "-c", forever, *run], cwd=ROOT, start_new_session=True)
    try:
        yield
    finally:
        os.killpg(loop.pid, signal.SIGTERM)
        loop.wait()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--problem", default=None)
    p.add_argument("--rounds", type=int, default=5, help="rounds of the paired comparison")
    p.add_argument(
        "--peers",
        type=Path,
        default=ROOT.parent / "shared" / "peers",
        help="folder with compare.py (default: ../shared/peers); missing: no comparison",
    )
    p.add_argument("--busy", action="store_true", help="measure beside a second job (a loop)")
    args = p.parse_args()
    with second_job(args.busy):
        measure(args)


def measure(args) -> None:
    # Time what `make` leaves behind: the package compiled (an editable install is not,
    # and where PYTHONDONTWRITEBYTECODE is set every run would compile it again).
    subprocess.run([sys.executable, "-m", "compileall", "-q", str(ROOT / "cake_drake")], check=True)
    busy = " (beside a second job: a cake_drake run in a loop)" if args.busy else ""
    print(f"machine: {machine()}{busy}")
    print(f"median of {args.repeats} runs per row; every run builds the tower (exit 0)\n")
    head = ["mode", "process s", "CPU s", "peak MiB", "sim s", "RTF"]
    head += [*[f"{s} s" for s in STAGES], "max err mrad"]
    print(" | ".join(head))
    print(" | ".join("---" for _ in head))
    replay = None
    rows = [("position", []), ("torque", []), ("torque replay", None)]
    # The same torque run from the cameras (docs/perception.md): the perception layer's cost.
    rows += [("torque, depth", ["--perception", "depth"]),
             ("torque, depth+noise", ["--perception", "depth", "--depth-noise"])]  # fmt: skip
    if importlib.util.find_spec("lerobot") is not None and not args.problem:
        # The learned layers' shipped runs (the lerobot extra): a state policy in the slot,
        # the learned skills under the planner.
        rows += [(name, []) for name in LEARNED]
    for mode, extra in rows:
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
        run_args = ["--mode", mode.split()[0].rstrip(",")]
        if mode in LEARNED:
            run_args = ["--scenario", str(LEARNING), "--name", mode]
        runs = [one_run(run_args, args.problem, extra) for _ in range(args.repeats)]

        def med(f, runs=runs):
            return statistics.median(f(r) for r in runs)

        cells = [
            mode,
            f"{med(lambda r: r['process_s']):.2f}",
            f"{med(lambda r: r['cpu_s']):.2f}",
            f"{med(lambda r: r['peak_mib']):.0f}",
            f"{med(lambda r: r['sim_s']):.1f}",
            f"{med(lambda r: r['rtf']):.1f}",
            *[f"{med(lambda r, s=s: r['stages_s'].get(s, 0.0)):.3f}" for s in STAGES],
            f"{med(lambda r: max(r['tracking_error']['max_rad'])) * 1000:.1f}",
        ]
        print(" | ".join(cells))
    compare = args.peers / "compare.py"
    if not compare.exists():
        print(f"\n{compare} not found: no comparison with the peers")
        return
    print(f"\nside by side with the peers ({compare}, {args.rounds} rounds):", flush=True)
    code = subprocess.run(
        [sys.executable, str(compare), "--rounds", str(args.rounds), "--project", str(ROOT)]
    ).returncode
    if code:
        sys.exit(f"{compare} failed (exit {code}); its output is above")


if __name__ == "__main__":
    main()
