"""``gains``: the Kd study, one recorded reference replayed through the IDC per Kd.

The study is the library's (:mod:`cake_drake.gains`); this module parses its flags.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cake_drake.commands.common import CliParser, add_set_flag
from cake_drake.errors import EXIT_OK

GAINS_DOC = """Gains study: replay one recorded trajectory through InverseDynamicsController per Kd.

Exercise 4.x.3 asks what happens to tracking when the derivative gain drops from 20 to
5. The study replays the same reference (--reference, or one recorded first by a
position-mode run of the scenario's task) once per Kd, with the same Kp, and writes
kd_comparison.png (joint 4's tracking error and torque, one trace per Kd) and gains.json
(per Kd: RMS and max tracking error per joint, settling times, whether the tower was
built, measured from the poses). Then it measures the lesson against theory: a step on
every joint per Kd (overshoot and 2 % settling time beside those of e'' + Kd e' + Kp e
= 0), and an unmodelled payload at the hand without and with integral action
(step_response.png, the "theory" section of gains.json).

Exit codes: 0 study done (whatever the towers did); 2 bad input; 3 the reference could
not be recorded.
"""


def gains_parser() -> argparse.ArgumentParser:
    p = CliParser(
        prog="python -m cake_drake.gains",
        description=GAINS_DOC,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--scenario", type=Path, help="base scenario (its task and world)")
    p.add_argument("--name", help="which scenario of a file that holds several")
    p.add_argument("--kd", type=float, nargs="+", default=[20.0, 5.0], help="Kd values (1/s)")
    p.add_argument("--kp", type=float, default=100.0, help="Kp for every run (1/s^2)")
    p.add_argument(
        "--reference",
        type=Path,
        help="trajectory.npz to replay (default: record one in position mode)",
    )
    p.add_argument("--differentiate", choices=("spline", "central"), default="spline")
    p.add_argument(
        "--problem",
        type=Path,
        help="the problem the reference was (or is to be) recorded on (default: problem_5)",
    )
    p.add_argument("--out", type=Path, default=Path("outputs"), help="output folder")
    p.add_argument("--quiet", action="store_true")
    add_set_flag(p, "the scenario")
    return p


def main_gains(argv: list[str] | None = None) -> int:
    from cake_drake.gains import GAINS_OUTPUTS, format_table, gains_inputs, write_study
    from cake_drake.outputs.files import check_output_folder
    from cake_drake.scenario import (
        ComputedTorque,
        Recorded,
        Scenario,
        load_scenario,
        portable_path,
        with_settings,
    )  # fmt: skip

    args = gains_parser().parse_args(argv)
    base = (load_scenario(args.scenario, args.name, args.set) if args.scenario
            else with_settings(Scenario(), args.set))  # fmt: skip
    base.controller = ComputedTorque(kp=[args.kp])
    if args.problem is not None:
        base.task.problem = portable_path(args.problem)
    if args.reference is not None:
        base.reference = Recorded(portable_path(args.reference), args.differentiate)
    check_output_folder(args.out, "gains", GAINS_OUTPUTS, gains_inputs(base))
    table = write_study(base, args.kd, args.out)
    print(format_table(table))
    if not args.quiet:
        print(
            f"wrote {args.out}/kd_comparison.png, step_response.png and gains.json",
            file=sys.stderr,
        )
    return EXIT_OK
