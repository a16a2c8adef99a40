"""Gains study: replay one recorded trajectory through InverseDynamicsController per Kd.

Exercise 4.x.3 asks what happens to tracking when the derivative gain drops from 20 to
5. :func:`study` replays the same reference once per Kd, with the same Kp, from a base
scenario (its task, world and reference; a planned reference is first recorded by a
position-mode run). The replays are a sweep over ``controller.kd``
(:mod:`cake_drake.sweeps`), run in parallel on a local pool, each keeping its measured
logs; it returns:

* the content of ``gains.json`` - per Kd: RMS and max tracking error per joint (rad),
  settling time after each waypoint, and whether the tower was built (measured from the
  poses);
* one :class:`Replay` per Kd (its logs), for :func:`comparison_plot` (``kd_comparison.png``).

``step`` holds the lesson against theory (a step response, an unmodelled payload).
``python -m cake_drake.gains`` is the command (``gains/__main__.py``; its parsing lives
with the other commands', which the library never imports).
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Sequence
from copy import deepcopy
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from cake_drake.dynamic.analysis import settling
from cake_drake.errors import ExecutionError, InputError
from cake_drake.execution import Logs
from cake_drake.formats import read_npz
from cake_drake.outputs.files import OutputDir
from cake_drake.paths import resolve_path
from cake_drake.pipeline import check, run, run_inputs
from cake_drake.scenario import ComputedTorque, JointPd, Recorded, Scenario
from cake_drake.sweeps import LocalPool, Sweep, run_sweep

FINAL_HOLD_S = 1.0


@dataclass
class Replay:
    """One Kd's replay: the verdict, the measured logs and the Kp/Kd it ran with."""

    kd: float
    kp: float
    success: bool
    message: str
    logs: Logs


def record_reference(base: Scenario, folder: Path) -> Path:
    """Run ``base``'s task in position mode into ``folder``; its trajectory.npz."""
    scenario = deepcopy(base)
    scenario.controller = JointPd()
    scenario.outputs.folder = str(folder)
    scenario.outputs.render = False
    scenario.visualization.meshcat = False
    recorded = run(scenario)
    if not recorded.success:
        raise ExecutionError(f"recording the reference failed: {recorded.message}")
    return folder / "trajectory.npz"


def study(
    base: Scenario, kds: Sequence[float], workdir: Path | None = None, engine=None
) -> tuple[dict, dict[float, Replay]]:
    """Replay ``base``'s reference once per Kd, with the Kp of its ``ComputedTorque``.

    A planned reference is first recorded by a position-mode run of the same task (into
    ``workdir/reference``). The replays are a sweep (into ``workdir/sweep``, or a
    temporary folder) on ``engine``: by default a local pool, one worker per Kd up to
    the machine's cores.
    """
    kds = list(kds)
    if not kds or any(not np.isfinite(k) or k < 0 for k in kds):
        raise InputError(f"--kd needs one or more finite values >= 0, got {kds}")
    if not isinstance(base.controller, ComputedTorque):
        raise InputError("the gains study varies a !ComputedTorque controller's kd")
    base.controller.check()
    kp = base.controller.kp
    if isinstance(base.reference, Recorded):
        reference = resolve_path(base.reference.path)
        differentiate = base.reference.differentiate
    else:
        reference = record_reference(base, (workdir or Path("outputs")) / "reference")
        differentiate = "spline"
    table: dict = {
        "kp": kp[0] if len(kp) == 1 else kp,
        "reference": str(reference),
        "differentiate": differentiate,
        "runs": [],
    }
    scenario = deepcopy(base)
    scenario.reference = Recorded(str(reference), differentiate)
    # A long final hold: the one stretch where the error can be watched decaying
    # undisturbed (the gripper holds mid-plan last 0.25 s with the fingers acting).
    scenario.simulation.settle_s = FINAL_HOLD_S
    scenario.visualization.meshcat = False
    scenario.outputs.render = False
    check(scenario, write=False)  # bad input is one line here, not a failed row per Kd
    sweep = Sweep.of(scenario, grid={"controller.kd": [[kd] for kd in kds]}, collect=["logs"])
    engine = engine or LocalPool(min(len(kds), LocalPool().workers))
    with tempfile.TemporaryDirectory(prefix="cake-drake-gains-") as tmp:
        out = (workdir / "sweep") if workdir is not None else Path(tmp)
        if workdir is not None:
            shutil.rmtree(out, ignore_errors=True)  # the study's own folder, run afresh
        swept = run_sweep(sweep, out, engine, progress=False)
        if swept.interrupted:
            raise KeyboardInterrupt
        results = {kd: _replay(out, row, kp) for kd, row in zip(kds, swept.rows, strict=True)}
    for kd, replay in results.items():
        logs = replay.logs
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
                "tower_built": replay.success,
                "message": replay.message,
            }
        )
    return table, results


#: The arrays of a replay's ``logs.npz`` the study reads (:class:`Logs`' fields; the
#: optional ones where the run logged them).
LOG_ARRAYS = {
    "t": ("N",), "q": ("N", 7), "v": ("N", 7), "q_d": ("N", 7), "v_d": ("N", 7),
    "a_d": ("N", 7), "fingers_d": ("N",), "phase": ("N",), "action": ("N",),
    "tau_commanded": ("N", 7), "tau_applied": ("N", 7),
}  # fmt: skip
LOG_OPTIONAL = {"tau_requested": ("N", 7), "gravity": ("N", 7), "fingers": ("N",)}


def _replay(out: Path, row: dict, kp: list[float]) -> Replay:
    """A finished row of the study's sweep, with the logs its run kept."""
    if row["status"] != "done":
        raise ExecutionError(
            f"the replay with Kd = {row['controller.kd']:g} failed: {row['error']}"
        )
    path = out / row["folder"] / "logs.npz"
    logs = Logs(**read_npz(path, "a run's logs.npz", LOG_ARRAYS, LOG_OPTIONAL))
    return Replay(row["controller.kd"], kp[0], bool(row["success"]), row["message"], logs)


#: The files a gains study writes.
GAINS_OUTPUTS = ("kd_comparison.png", "step_response.png", "gains.json", "reference.npz")


def gains_inputs(base: Scenario) -> list[Path]:
    """The files the study reads (none may be among the outputs it replaces)."""
    return run_inputs(base)


def write_study(base: Scenario, kds: Sequence[float], out: Path) -> dict:
    """Run :func:`study` and write ``kd_comparison.png`` and ``gains.json`` to ``out``
    (and ``reference.npz``, the recorded reference, when the study recorded one).

    The study works in a temporary folder; ``out`` is replaced whole at the end.
    """
    from cake_drake.gains import step

    with tempfile.TemporaryDirectory(prefix="cake-drake-gains-") as tmp:
        table, results = study(base, kds, Path(tmp))
        kp = float(table["kp"] if np.ndim(table["kp"]) == 0 else table["kp"][0])
        table["theory"], responses = step.study(kp, list(kds))
        with OutputDir(out, "gains", GAINS_OUTPUTS, gains_inputs(base)) as staged:
            recorded = Path(tmp) / "reference" / "trajectory.npz"
            if recorded.exists():
                shutil.copyfile(recorded, staged.path("reference.npz"))
                table["reference"] = "reference.npz"
            comparison_plot(results, staged.path("kd_comparison.png"))
            step.plot(responses, kp, staged.path("step_response.png"))
            staged.write_json("gains.json", table)
            staged.commit()
    return table


def comparison_plot(
    results: dict[float, Replay], path: Path | None = None, joint: int = 4
) -> Figure:
    """Joint ``joint``'s tracking error (left) and commanded torque (right), one trace per Kd."""
    from cake_drake.outputs.plots import phase_key, phase_spans, shade_phases

    j = joint - 1
    fig = Figure(figsize=(13, 4.5))
    ax_e, ax_t = fig.subplots(1, 2, sharex=True)
    first = next(iter(results.values())).logs
    spans = phase_spans(first.t, first.phase)
    shade_phases(ax_e, spans)
    shade_phases(ax_t, spans)
    for kd, result in results.items():
        logs = result.logs
        ax_e.plot(logs.t, (logs.q[:, j] - logs.q_d[:, j]) * 1000, lw=0.9, label=f"Kd = {kd:g}")
        ax_t.plot(logs.t, logs.tau_commanded[:, j], lw=0.9, label=f"Kd = {kd:g}")
    ax_e.set_ylabel(f"joint {joint}: q − q_d [mrad]")
    ax_t.set_ylabel(f"joint {joint}: τ commanded [N·m]")
    for ax in (ax_e, ax_t):
        ax.set_xlabel("time [s]")
        ax.legend(loc="lower right", fontsize=8)
    kp = next(iter(results.values())).kp
    fig.suptitle(f"Computed torque, Kp = {kp:g}: tracking error and torque as Kd changes", y=0.99)
    phase_key(fig)
    fig.tight_layout(rect=(0, 0, 1, 0.88))
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig


def format_table(table: dict) -> str:
    from cake_drake.gains.step import format_study

    lines = [
        f"the run replayed, Kp = {table['kp']:g}; reference {table['reference']}",
        f"{'Kd':>6} {'RMS err j4 [mrad]':>18} {'max err j4 [mrad]':>18} "
        f"{'max err j5-7 [mrad]':>20} {'max err all [mrad]':>19} {'tower':>6}",
    ]
    for r in table["runs"]:
        m = r["max_tracking_error"]
        lines.append(
            f"{r['kd']:>6g} {r['rms_tracking_error'][3] * 1000:>18.3f} "
            f"{m[3] * 1000:>18.3f} {max(m[4:]) * 1000:>20.3f} {max(m) * 1000:>19.3f} "
            f"{'yes' if r['tower_built'] else 'no':>6}"
        )
    if "theory" in table:
        kp = table["kp"] if np.ndim(table["kp"]) == 0 else table["kp"][0]
        lines += format_study(table["theory"], kp)
    return "\n".join(lines)
