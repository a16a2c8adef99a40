"""The local pool's speed-up: one sweep with one worker, then with one per core.

    python benchmarks/sweep.py [SWEEP.yaml ...] [--workers N]

Each sweep is a whole `python -m cake_drake.sweep` process (worker start-up, imports and
the table included); the speed-up is the serial wall time over the pool's. "CPU s" is
the processor time the sweep's processes used (workers and their helpers included);
CPU s / wall s is how many cores the sweep actually got, which on a machine shared with
other work is less than the pool's size. Both runs must give the same table (apart
from timings), which is checked.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from machine import machine  # benchmarks/machine.py

from cake_drake.sweeps import read_table
from cake_drake.sweeps.worker import TIMINGS

ROOT = Path(__file__).resolve().parent.parent


def _cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def one_sweep(path: Path, workers: int) -> tuple[float, float, list[dict]]:
    with tempfile.TemporaryDirectory() as out:
        cmd = [sys.executable, "-m", "cake_drake.sweep", str(path), "--out", out, "--quiet"]
        t0, cpu0 = time.perf_counter(), _cpu()
        r = subprocess.run([*cmd, "--workers", str(workers)], capture_output=True, text=True)
        wall, cpu = time.perf_counter() - t0, _cpu() - cpu0
        if r.returncode != 0:
            sys.exit(f"sweep failed ({r.returncode}): {r.stderr.strip()}")
        rows = read_table(Path(out) / "results.parquet")
    return wall, cpu, [{k: v for k, v in row.items() if k not in TIMINGS} for row in rows]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("sweeps", nargs="*", type=Path, default=[ROOT / "models/sweeps/smoke.yaml"])
    p.add_argument("--workers", type=int, default=os.cpu_count(), help="the pool's size")
    args = p.parse_args()
    print(machine())
    n = args.workers
    print(f"sweep | runs | 1 worker: wall s (CPU s) | {n} workers: wall s (CPU s) | speed-up")
    print("--- | --- | --- | --- | ---")
    for path in args.sweeps:
        serial, cpu_1, rows_1 = one_sweep(path, 1)
        pool, cpu_n, rows_n = one_sweep(path, n)
        same = "" if rows_1 == rows_n else " (tables differ!)"
        print(
            f"{path.name} | {len(rows_1)} | {serial:.1f} ({cpu_1:.1f}) | {pool:.1f} ({cpu_n:.1f}) "
            f"| {serial / pool:.2f}x{same}"
        )


if __name__ == "__main__":
    main()
