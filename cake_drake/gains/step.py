"""The Kd lesson against theory: a step response under computed torque, and a payload the
controller's model does not know.

With a model that matches the arm, computed torque leaves every joint's error
e = q - q_d obeying  ë + Kd ė + Kp e = 0 : a mass-spring-damper of natural frequency
ω = √Kp and damping ratio ζ = Kd / (2√Kp) (1.0 at Kp 100, Kd 20: critically damped; 0.25
at Kd 5). :func:`step_response` starts the arm still at ``Q_HOME`` with the reference a
``step`` (rad) away on every joint at once (q̇_d = q̈_d = 0) and measures, per joint, the
overshoot (how far the error swings past zero, as a fraction of the step) and the 2 %
settling time, beside :func:`theory`'s.

:func:`payload_response` hangs an unmodelled mass's weight at the grasp frame (a
constant downward force: the tool or heavy cube the control plant does not have) and
holds the reference still: the arm sags by a steady error no Kp or Kd removes; integral
action (``ki``) does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: rad, the step on every joint.
STEP_RAD = 0.05
#: The band of the settling time: within 2 % of the step.
BAND = 0.02


@dataclass(frozen=True)
class Theory:
    zeta: float
    overshoot: float  # fraction of the step
    settling_s: float  # into the 2 % band


def theory(kp: float, kd: float) -> Theory:
    """Overshoot and 2 % settling time of ë + kd ė + kp e = 0 from e(0) = 1, ė(0) = 0."""
    wn = math.sqrt(kp)
    zeta = kd / (2 * wn)
    overshoot = math.exp(-zeta * math.pi / math.sqrt(1 - zeta**2)) if zeta < 1 else 0.0
    t = np.linspace(0.0, 20.0 / wn, 20001)
    e = _free_response(t, wn, zeta)
    outside = np.flatnonzero(np.abs(e) > BAND)
    settling = float(t[outside[-1] + 1]) if len(outside) else 0.0
    return Theory(zeta, overshoot, settling)


def _free_response(t: np.ndarray, wn: float, zeta: float) -> np.ndarray:
    """e(t) with e(0) = 1, ė(0) = 0."""
    if zeta < 1:
        wd = wn * math.sqrt(1 - zeta**2)
        return np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta * wn / wd * np.sin(wd * t))
    if zeta == 1:
        return np.exp(-wn * t) * (1 + wn * t)
    r1 = -wn * (zeta - math.sqrt(zeta**2 - 1))
    r2 = -wn * (zeta + math.sqrt(zeta**2 - 1))
    return (r2 * np.exp(r1 * t) - r1 * np.exp(r2 * t)) / (r2 - r1)


@dataclass
class Response:
    """A simulated response: time, the error per joint (rad), and its measures."""

    t: np.ndarray
    error: np.ndarray  # (T, 7), q - q_d
    overshoot: np.ndarray  # (7,) fraction of the step
    settling_s: np.ndarray  # (7,)
    steady: np.ndarray  # (7,) mean error over the last 0.5 s (rad)


def _simulate(kp: float, kd: float, ki: float, q0, q_d, payload_kg: float, duration_s: float,
              time_step: float) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    from pydrake.common.value import AbstractValue
    from pydrake.multibody.math import SpatialForce
    from pydrake.multibody.plant import ExternallyAppliedSpatialForce
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import (
        ConstantValueSource,
        ConstantVectorSource,
        LogVectorOutput,
    )

    from cake_drake.dynamic.controllers import ComputedTorque
    from cake_drake.world.scene import WorldConfig, add_world, make_control_plant

    builder = DiagramBuilder()
    scene = add_world(builder, [], WorldConfig(time_step=time_step))
    scene.control_plant = make_control_plant()
    plant = scene.plant
    desired = builder.AddSystem(ConstantVectorSource(np.r_[q_d, np.zeros(7)]))
    zero = builder.AddSystem(ConstantVectorSource(np.zeros(7)))
    controller = ComputedTorque(kp=[kp], kd=[kd], ki=[ki])
    controller.add_to(builder, scene, desired.get_output_port(), zero.get_output_port())
    fingers = builder.AddSystem(ConstantVectorSource([0.04, 0.04, 0.0, 0.0]))  # held open
    builder.Connect(fingers.get_output_port(), plant.get_desired_state_input_port(scene.hand))
    if payload_kg > 0:
        hand = plant.GetBodyByName("panda_hand", scene.hand)
        grasp = plant.GetFrameByName("grasp", scene.hand).GetFixedPoseInBodyFrame()
        force = ExternallyAppliedSpatialForce()
        force.body_index = hand.index()
        force.p_BoBq_B = grasp.translation()
        force.F_Bq_W = SpatialForce([0.0, 0.0, 0.0], [0.0, 0.0, -9.81 * payload_kg])
        source = builder.AddSystem(ConstantValueSource(AbstractValue.Make([force])))
        builder.Connect(source.get_output_port(), plant.get_applied_spatial_force_input_port())
    log = LogVectorOutput(plant.get_state_output_port(scene.arm), builder, time_step)
    diagram = builder.Build()
    sim = Simulator(diagram)
    ctx = plant.GetMyMutableContextFromRoot(sim.get_mutable_context())
    plant.SetPositions(ctx, scene.arm, q0)
    plant.SetPositions(ctx, scene.hand, [0.04, 0.04])
    sim.AdvanceTo(duration_s)
    data = log.FindLog(sim.get_context())
    return data.sample_times(), data.data()[:7].T


def _measure(t, error) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Overshoot and settling time of each joint's error relative to where it ends up
    (the mean over the last 0.5 s): a joint whose model is off settles beside zero, and
    that offset is not an overshoot."""
    steady = error[t >= t[-1] - 0.5].mean(axis=0)
    start = error[0] - steady
    x = (error - steady) / np.where(np.abs(start) > 1e-12, start, 1.0)  # 1 towards 0
    overshoot = np.maximum(0.0, -np.min(x, axis=0))
    settling = np.zeros(7)
    for j in range(7):
        outside = np.flatnonzero(np.abs(x[:, j]) > BAND)
        settling[j] = t[min(outside[-1] + 1, len(t) - 1)] if len(outside) else 0.0
    return overshoot, settling, steady


def step_response(kp: float = 100.0, kd: float = 20.0, ki: float = 0.0, step: float = STEP_RAD,
                  duration_s: float = 3.0, time_step: float = 0.001) -> Response:  # fmt: skip
    """Every joint's error after a ``step`` of the reference from rest at ``Q_HOME``."""
    from cake_drake.world.scene import Q_HOME

    q0 = np.asarray(Q_HOME, float)
    t, q = _simulate(kp, kd, ki, q0, q0 + step, 0.0, duration_s, time_step)
    error = q - (q0 + step)
    return Response(t, error, *_measure(t, error))


def payload_response(payload_kg: float, kp: float = 100.0, kd: float = 20.0, ki: float = 0.0,
                     duration_s: float = 6.0, time_step: float = 0.001) -> Response:  # fmt: skip
    """The arm held at ``Q_HOME`` with ``payload_kg`` hanging at the grasp frame unmodelled."""
    from cake_drake.world.scene import Q_HOME

    q0 = np.asarray(Q_HOME, float)
    t, q = _simulate(kp, kd, ki, q0, q0, payload_kg, duration_s, time_step)
    error = q - q0
    return Response(t, error, *_measure(t, error))


#: The unmodelled payload of the mismatch study (kg, at the grasp frame), and the
#: integral gain that removes its steady error (stable while Ki < Kp * Kd).
PAYLOAD_KG = 0.5
KI = 200.0


def study(kp: float, kds: list[float]) -> tuple[dict, dict]:
    """The step response at each Kd and the payload at the first Kd without and with
    integral action: (the ``gains.json`` section, the responses for :func:`plot`)."""
    steps = {kd: step_response(kp, kd) for kd in kds}
    payload = {ki: payload_response(PAYLOAD_KG, kp, kds[0], ki) for ki in (0.0, KI)}
    table = {
        "step_rad": STEP_RAD,
        "band": BAND,
        "step": [],
        "payload": {
            "kg": PAYLOAD_KG,
            "kd": kds[0],
            "runs": [
                {"ki": ki, "steady_error_rad": r.steady.round(6).tolist()}
                for ki, r in payload.items()
            ],
        },
    }
    for kd, r in steps.items():
        th = theory(kp, kd)
        table["step"].append(
            {
                "kd": kd,
                "zeta": round(th.zeta, 4),
                "overshoot_theory": round(th.overshoot, 4),
                "overshoot": r.overshoot.round(4).tolist(),
                "settling_theory_s": round(th.settling_s, 3),
                "settling_s": r.settling_s.round(3).tolist(),
            }
        )
    return table, {"step": steps, "payload": payload}


def format_study(table: dict, kp: float) -> list[str]:
    """The printed lines: per Kd, theory beside the worst joint; the payload's sag."""
    lines = [
        f"step of {table['step_rad']:g} rad on every joint (error e'' + Kd e' + Kp e = 0, "
        f"zeta = Kd / (2 sqrt(Kp)), Kp = {kp:g}):",
        f"{'Kd':>6} {'zeta':>6} {'overshoot theory':>17} {'measured, worst joint':>22} "
        f"{'settle 2% theory':>17} {'measured, worst joint':>22}",
    ]
    for r in table["step"]:
        o, s = np.asarray(r["overshoot"]), np.asarray(r["settling_s"])
        jo = int(np.argmax(np.abs(o - r["overshoot_theory"])))
        js = int(np.argmax(np.abs(s - r["settling_theory_s"])))
        lines.append(
            f"{r['kd']:>6g} {r['zeta']:>6.2f} {r['overshoot_theory'] * 100:>16.1f}% "
            f"{o[jo] * 100:>13.1f}% (j{jo + 1})  {r['settling_theory_s']:>15.2f} s "
            f"{s[js]:>13.2f} s (j{js + 1})"
        )
    p = table["payload"]
    sag = [np.abs(np.asarray(run["steady_error_rad"])) for run in p["runs"]]
    lines.append(
        f"an unmodelled {p['kg']:g} kg at the hand, Kd {p['kd']:g}: steady error up to "
        f"{sag[0].max() * 1000:.1f} mrad (j{int(np.argmax(sag[0])) + 1}) with Ki 0, "
        f"{sag[1].max() * 1000:.2f} mrad with Ki {p['runs'][1]['ki']:g}"
    )
    return lines


def plot(responses: dict, kp: float, path=None):
    """Left: every joint's step error, normalised, per Kd, over theory's curve. Right: the
    payload's sag per joint, without and with integral action."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(13, 4.5))
    ax_s, ax_p = fig.subplots(1, 2)
    colours = ["tab:blue", "tab:red", "tab:green", "tab:purple"]
    for (kd, r), colour in zip(responses["step"].items(), colours, strict=False):
        x = (r.error - r.steady) / (r.error[0] - r.steady)
        ax_s.plot(r.t, x, color=colour, lw=0.8, alpha=0.6)
        th = theory(kp, kd)
        ax_s.plot(r.t, _free_response(r.t, math.sqrt(kp), th.zeta), "--", color="black", lw=1)
        ax_s.plot([], [], color=colour, label=f"Kd = {kd:g} (ζ = {th.zeta:.2f}): 7 joints")
    ax_s.plot([], [], "--", color="black", label="theory: ë + Kd ė + Kp e = 0")
    ax_s.axhspan(-BAND, BAND, color="0.85", zorder=0)
    ax_s.set_xlabel("time after the step [s]")
    ax_s.set_ylabel("error / step")
    ax_s.set_title(f"step of {STEP_RAD:g} rad on every joint, Kp = {kp:g}", fontsize=10)
    ax_s.legend(fontsize=8, loc="upper right")
    for (ki, r), style in zip(responses["payload"].items(), ("-", ":"), strict=True):
        for j in range(7):
            ax_p.plot(r.t, r.error[:, j] * 1000, style, color=f"C{j}", lw=1,
                      label=f"joint {j + 1}" if ki == 0 else None)  # fmt: skip
    ax_p.plot([], [], "-", color="black", label="Ki = 0")
    ax_p.plot([], [], ":", color="black", label=f"Ki = {KI:g}")
    ax_p.set_xlabel("time [s]")
    ax_p.set_ylabel("q − q_d [mrad]")
    ax_p.set_title(f"an unmodelled {PAYLOAD_KG:g} kg at the hand: the sag and integral action",
                   fontsize=10)  # fmt: skip
    ax_p.legend(fontsize=7, ncol=3, loc="lower right")
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig
