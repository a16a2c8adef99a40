"""``sweep``: many runs of a sweep file in parallel (a local pool or Ray), one table.

The sweep is the library's (:mod:`cake_drake.sweeps`); this module parses its flags.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cake_drake.commands.common import CliParser, add_set_flag
from cake_drake.errors import EXIT_OK

SWEEP_DOC = """Run a sweep: many scenarios in parallel, one table of results, plots.

A sweep file is a base scenario plus axes over its fields (a grid, a list of cases)
and a number of seeds (models/sweeps/ has the shipped ones). Each run is built and
simulated inside its worker; a run that fails or crashes is a row with its error.
Writes to --out: results.parquet and results.csv (each run's parameters and metrics),
plots/ (one figure per axis), and runs/<id>/ per run with its outputs and the resolved
scenario.yaml (re-run one alone with python -m cake_drake.run --scenario ...).

Engines: a local pool of spawned processes (--workers N, default one per core), or
Ray: --ray starts a local instance, --ray ADDRESS joins a cluster (auto, or HOST:PORT;
every node needs cake_drake installed, pip install 'cake_drake[ray]').

Exit codes: 0 the sweep finished (whatever its runs did: see the table); 2 bad input
(a bad sweep file: unknown field, empty axis, wrong value); 130 interrupted (what
finished is kept: --resume runs the rest).
"""


def sweep_parser() -> argparse.ArgumentParser:
    p = CliParser(
        prog="python -m cake_drake.sweep",
        description=SWEEP_DOC,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("sweep", type=Path, metavar="SWEEP.yaml", help="the sweep file")
    p.add_argument("--out", type=Path, help="output folder (default: outputs/sweeps/NAME)")
    engine = p.add_mutually_exclusive_group()
    engine.add_argument("--workers", type=int, help="local worker processes (default: cores)")
    engine.add_argument(
        "--ray",
        nargs="?",
        const="",
        metavar="ADDRESS",
        help="run on Ray: a local instance, or the cluster at ADDRESS (auto | HOST:PORT)",
    )
    p.add_argument("--resume", action="store_true", help="keep finished runs, run the rest")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_set_flag(p, "the sweep's base scenario")
    return p


def main_sweep(argv: list[str] | None = None) -> int:
    from cake_drake.scenario import with_settings
    from cake_drake.sweeps import LocalPool, RayCluster, load_sweep, run_sweep

    args = sweep_parser().parse_args(argv)
    sweep = load_sweep(args.sweep)
    if args.set:  # the base as run, and in the folder's copy of the file, what changed it
        sweep.base = with_settings(sweep.base, args.set)
        sweep.text += "".join(f"# run with --set {given}\n" for given in args.set)
    out = args.out or Path("outputs") / "sweeps" / args.sweep.stem
    engine = LocalPool(args.workers) if args.ray is None else RayCluster(args.ray or None)
    if not args.quiet:
        print(f"{args.sweep}: {len(sweep.runs())} runs on a {engine}", file=sys.stderr)
    result = run_sweep(sweep, out, engine, resume=args.resume, progress=not args.quiet)
    done = result.count("done")
    won = sum(bool(r["success"]) for r in result.rows)
    failed = len(result.rows) - done
    kept = f" ({result.skipped} kept from before)" if result.skipped else ""
    print(
        f"{len(result.rows)}/{result.total} runs{kept}: {done} done ({won} reached the goal), "
        f"{failed} failed; table in {out}/results.parquet and results.csv, plots in {out}/plots/"
    )
    if result.interrupted:
        print("error: interrupted: what finished is kept; --resume runs the rest", file=sys.stderr)
        return 130
    return EXIT_OK
