"""Gains study: replay one recorded trajectory through InverseDynamicsController per Kd.

Exercise 4.x.3 asks what happens to tracking when the derivative gain drops from 20 to
5. This tool replays the same reference (``--reference``, or one recorded first by a
position-mode run) once per Kd, with the same Kp, and writes:

* ``kd_comparison.png`` - joint 4's tracking error and torque, one trace per Kd;
* ``gains.json`` - per Kd: RMS and max tracking error per joint (rad), settling time
  after each waypoint, and whether the tower was built (measured from the poses).

Exit codes: 0 study done (whatever the towers did); 2 bad input; 3 the reference could
not be recorded.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from cake_drake.diagram import RunConfig
from cake_drake.dynamic.analysis import settling
from cake_drake.errors import EXIT_OK, CliParser, ExecutionError, InputError, run_cli
from cake_drake.outputs.files import OutputDir
from cake_drake.run import RunResult, run
from cake_drake.symbolic import PROBLEM_5

FINAL_HOLD_S = 1.0


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = CliParser(
        prog="python -m cake_drake.gains",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--kd", type=float, nargs="+", default=[20.0, 5.0], help="Kd values (1/s)")
    p.add_argument("--kp", type=float, default=100.0, help="Kp for every run (1/s^2)")
    p.add_argument(
        "--reference",
        type=Path,
        default=None,
        help="trajectory.npz to replay (default: record one in position mode)",
    )
    p.add_argument("--differentiate", choices=("spline", "central"), default="spline")
    p.add_argument(
        "--problem",
        type=Path,
        default=PROBLEM_5,
        help="the problem the reference was (or is to be) recorded on (default: problem_5)",
    )
    p.add_argument("--out", type=Path, default=Path("outputs"), help="output folder")
    p.add_argument("--quiet", action="store_true")
    return p.parse_args(argv)


def study(
    kds: list[float],
    kp: float = 100.0,
    reference: Path | None = None,
    differentiate: str = "spline",
    workdir: Path | None = None,
    problem_path: Path = PROBLEM_5,
) -> tuple[dict, dict[float, RunResult]]:
    """Replay ``reference`` once per Kd; returns (gains.json content, results by Kd).

    ``reference`` must have been recorded on ``problem_path`` (the replay lays out the
    same cubes); without one, a position-mode run of that problem records it.
    """
    if not kds or any(k < 0 for k in kds):
        raise InputError(f"--kd needs one or more values >= 0, got {kds}")
    if kp <= 0:
        raise InputError(f"--kp must be > 0, got {kp}")
    if reference is None:
        workdir = workdir or Path("outputs")
        recorded = run(
            RunConfig(mode="position"),
            problem_path=problem_path,
            out=workdir / "reference",
            render=False,
        )
        if not recorded.success:
            raise ExecutionError(f"recording the reference failed: {recorded.message}")
        reference = workdir / "reference" / "trajectory.npz"
    results: dict[float, RunResult] = {}
    table: dict = {
        "kp": kp,
        "reference": str(reference),
        "differentiate": differentiate,
        "runs": [],
    }
    for kd in kds:
        config = RunConfig(
            mode="torque", kp=kp, kd=kd, reference=reference, differentiate=differentiate
        )
        # A long final hold: the one stretch where the error can be watched decaying
        # undisturbed (the gripper holds mid-plan last 0.25 s with the fingers acting).
        result = run(config, problem_path=problem_path, out=None, settle_s=FINAL_HOLD_S)
        results[kd] = result
        logs = result.execution.logs
        err = logs.q - logs.q_d
        s = settling(logs.t, logs.q, logs.q_d, logs.v_d)
        table["runs"].append(
            {
                "kd": kd,
                "rms_tracking_error": np.sqrt(np.mean(err**2, axis=0)).round(7).tolist(),
                "max_tracking_error": np.max(np.abs(err), axis=0).round(7).tolist(),
                "settling_threshold_rad": s.threshold,
                "settling_time_s": {
                    "median": round(s.median, 3),
                    "max": round(s.worst, 3),
                    "per_waypoint": [round(x, 3) for x in s.times],
                    "never_settled": int(sum(not ok for ok in s.settled)),
                    "final_hold": round(s.times[-1], 3) if s.times else None,
                },
                "tower_built": result.success,
                "message": result.message,
            }
        )
    return table, results


def comparison_plot(
    results: dict[float, RunResult], path: Path | None = None, joint: int = 4
) -> Figure:
    """Joint ``joint``'s tracking error (left) and commanded torque (right), one trace per Kd."""
    from cake_drake.outputs.plots import phase_key, phase_spans, shade_phases

    j = joint - 1
    fig = Figure(figsize=(13, 4.5))
    ax_e, ax_t = fig.subplots(1, 2, sharex=True)
    first = next(iter(results.values())).execution.logs
    spans = phase_spans(first.t, first.phase)
    shade_phases(ax_e, spans)
    shade_phases(ax_t, spans)
    for kd, result in results.items():
        logs = result.execution.logs
        ax_e.plot(logs.t, (logs.q[:, j] - logs.q_d[:, j]) * 1000, lw=0.9, label=f"Kd = {kd:g}")
        ax_t.plot(logs.t, logs.tau_commanded[:, j], lw=0.9, label=f"Kd = {kd:g}")
    ax_e.set_ylabel(f"joint {joint}: q − q_d [mrad]")
    ax_t.set_ylabel(f"joint {joint}: τ commanded [N·m]")
    for ax in (ax_e, ax_t):
        ax.set_xlabel("time [s]")
        ax.legend(loc="lower right", fontsize=8)
    kp = next(iter(results.values())).cake.config.gains()[0][j]
    fig.suptitle(f"Computed torque, Kp = {kp:g}: tracking error and torque as Kd changes", y=0.99)
    phase_key(fig)
    fig.tight_layout(rect=(0, 0, 1, 0.88))
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig


def format_table(table: dict) -> str:
    lines = [
        f"Kp = {table['kp']:g}; reference {table['reference']}",
        f"{'Kd':>6} {'RMS err j4 [mrad]':>18} {'max err j4 [mrad]':>18} "
        f"{'max err all [mrad]':>19} {'settle median/max [s]':>22} {'tower':>6}",
    ]
    for r in table["runs"]:
        st = r["settling_time_s"]
        lines.append(
            f"{r['kd']:>6g} {r['rms_tracking_error'][3] * 1000:>18.3f} "
            f"{r['max_tracking_error'][3] * 1000:>18.3f} "
            f"{max(r['max_tracking_error']) * 1000:>19.3f} "
            f"{st['median']:>10.3f} / {st['max']:<9.3f} {'yes' if r['tower_built'] else 'no':>6}"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.reference is not None and not args.reference.is_file():
        raise InputError(f"{args.reference}: no such file (expected a trajectory.npz from a run)")
    table, results = study(
        args.kd, args.kp, args.reference, args.differentiate, args.out, args.problem
    )
    out = OutputDir(args.out)
    try:
        comparison_plot(results, out.path("kd_comparison.png"))
        out.write_json("gains.json", table)
        out.commit()
    except BaseException:
        out.discard()
        raise
    print(format_table(table))
    if not args.quiet:
        print(f"wrote {args.out}/kd_comparison.png and {args.out}/gains.json", file=sys.stderr)
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(run_cli(main))
