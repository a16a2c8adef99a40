"""Fuzz every parser: N mutated inputs each, through the command-line entry points.

    python benchmarks/fuzz.py [--examples 10000]

Mutations (deletions, insertions, duplications, truncations) of the shipped domain and
problem, of a plan file and of a SayCan transcript go through `validate` and `saycan`
in-process. Prints, per parser, how many inputs ended with each exit code and how many
escaped the exit-code table (a traceback); exits 1 if any did.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import io
import sys
import tempfile
import time
import traceback
from pathlib import Path

from hypothesis import HealthCheck, given, settings

# The suite's own mutations (tests/contracts/test_hardening.py), run here by the ten thousand: the
# one benchmark that reads the tests' folder.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from test_hardening import EXIT_CODES, PLAN_5, TRANSCRIPT, mutated

from cake_drake.commands.saycan import main_saycan
from cake_drake.commands.validate import main_validate
from cake_drake.errors import run_cli
from cake_drake.symbolic import BLOCKSWORLD_DOMAIN, PROBLEM_5


def fuzz(name: str, strategy, call, examples: int) -> tuple[collections.Counter, list[str]]:
    codes: collections.Counter = collections.Counter()
    escaped: list[str] = []
    work = Path(tempfile.mkdtemp(prefix=f"fuzz_{name}_"))

    @settings(max_examples=examples, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))  # fmt: skip
    @given(strategy)
    def one(data):
        out, err = io.StringIO(), io.StringIO()
        try:
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                code = call(work, data)
        except BaseException:  # noqa: BLE001 - counted, not raised: the point of the fuzz
            escaped.append(traceback.format_exc(limit=3))
            return
        codes[code] += 1
        if code not in EXIT_CODES or "Traceback" in err.getvalue():
            escaped.append(f"exit {code}: {err.getvalue()[:300]}")

    one()
    return codes, escaped


def validate_pddl(work: Path, texts) -> int:
    domain, problem = texts
    (work / "d.pddl").write_text(domain)
    (work / "p.pddl").write_text(problem)
    (work / "plan.txt").write_text(PLAN_5)
    return run_cli(main_validate, [str(work / f) for f in ("d.pddl", "p.pddl", "plan.txt")])


def validate_plan(work: Path, plan: str) -> int:
    (work / "plan.txt").write_text(plan)
    return run_cli(main_validate, [str(BLOCKSWORLD_DOMAIN), str(PROBLEM_5), str(work / "plan.txt")])


def saycan(work: Path, transcript: str) -> int:
    (work / "t.txt").write_text(transcript)
    return run_cli(
        main_saycan, [str(work / "t.txt"), "--out", str(work / "out"), "--planner", "gbfs-ff"]
    )


def main() -> int:
    from hypothesis import strategies as st

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--examples", type=int, default=10000)
    args = parser.parse_args()
    cases = {
        "PDDL (domain + problem)": (
            st.tuples(mutated(BLOCKSWORLD_DOMAIN.read_text()), mutated(PROBLEM_5.read_text())),
            validate_pddl,
        ),
        "plan files": (mutated(PLAN_5 + "; cost = 5 (unit cost)\n"), validate_plan),
        "transcripts": (mutated(TRANSCRIPT), saycan),
    }
    failed = False
    print(f"{'parser':<26} {'inputs':>7} {'exit codes':<40} {'escaped':>7} {'s':>6}")
    for name, (strategy, call) in cases.items():
        t0 = time.perf_counter()
        codes, escaped = fuzz(name.split()[0].lower(), strategy, call, args.examples)
        spread = ", ".join(f"{k}: {v}" for k, v in sorted(codes.items()))
        n = sum(codes.values()) + len(escaped)
        print(f"{name:<26} {n:>7} {spread:<40} {len(escaped):>7} {time.perf_counter() - t0:>6.0f}")
        for e in escaped[:3]:
            print("  escaped:", e.strip().splitlines()[-1])
        failed |= bool(escaped)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
