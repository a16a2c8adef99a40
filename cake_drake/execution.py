"""Simulate a built :class:`~cake_drake.diagram.CakeDiagram` and measure the outcome.

The simulator advances in short chunks until every action is reported done (or an
action fails, or the time budget runs out), then lets the world settle and reads the
cube poses back as PDDL facts. Nothing here assumes success: the verdict is measured.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.analysis import Simulator

from cake_drake.diagram import CakeDiagram
from cake_drake.errors import CakeDrakeError
from cake_drake.perception.report import errors, summarize, truth_at
from cake_drake.plugins import budget, is_plugin, raised_in_simulation
from cake_drake.world.cameras import grab
from cake_drake.world.facts import Reading, read_facts, stack_offsets
from cake_drake.world.faults import move_cube
from cake_drake.world.scene import cube_poses, set_world_parameters


@dataclass
class Logs:
    """Everything the loggers recorded, as arrays over time ``t``."""

    t: np.ndarray
    q: np.ndarray  # (N, 7) measured arm positions
    v: np.ndarray  # (N, 7) measured arm velocities
    q_d: np.ndarray  # (N, 7) desired positions
    v_d: np.ndarray
    a_d: np.ndarray
    fingers_d: np.ndarray  # (N,) commanded finger opening
    phase: np.ndarray  # (N,) phase index
    action: np.ndarray  # (N,) action index (-1 idle)
    tau_commanded: np.ndarray  # (N, 7) controller output
    tau_applied: np.ndarray  # (N, 7) net actuation on the arm joints (PD included)
    tau_requested: np.ndarray | None = None  # (N, 7) actuation asked of the arm, before limits
    gravity: np.ndarray | None = None  # (N, 7) g(q): the torque that holds the arm still
    fingers: np.ndarray | None = None  # (N,) one finger's measured opening (m)

    def saturation(self, limits) -> dict:
        """Per joint: the time (s) the torque sat at its limit, and the peak asked (N m).

        A joint is saturated at a sample when the torque requested of its actuator exceeds
        the limit, or when the applied torque (the plant's built-in PD included, which the
        plant clamps itself) reaches it.
        """
        limits = np.asarray(limits, dtype=float)
        asked = self.tau_applied if self.tau_requested is None else self.tau_requested
        peak = np.maximum(np.abs(asked), np.abs(self.tau_applied))
        at_limit = (np.abs(asked) > limits) | (np.abs(self.tau_applied) >= limits * (1 - 1e-6))
        dt = float(np.median(np.diff(self.t))) if len(self.t) > 1 else 0.0
        return {
            "limits_nm": limits.tolist(),
            "saturated_s": (at_limit.sum(axis=0) * dt).round(3).tolist(),
            "peak_nm": (peak.max(axis=0) if len(peak) else np.zeros(7)).round(2).tolist(),
        }

    def tracking_error(self) -> dict[str, list[float]]:
        e = self.q - self.q_d
        return {
            "rms_rad": np.sqrt(np.mean(e**2, axis=0)).round(6).tolist(),
            "max_rad": np.max(np.abs(e), axis=0).round(6).tolist(),
        }


@dataclass
class Execution:
    """What happened in the simulated world."""

    sim_s: float
    wall_s: float
    actions_done: int
    n_actions: int
    error: str | None
    poses: dict[str, RigidTransform]
    reading: Reading
    offsets: dict[str, float]
    logs: Logs
    warnings: tuple[str, ...]  # collisions found along the planned moves
    q_final: np.ndarray  # arm joints at the end
    fingers_final: float  # opening of one finger at the end (m)
    actions: tuple[str, ...] = ()  # the actions executed, in order
    #: Why a policy stopped acting when not by its own word ("the policy's step budget ...").
    ended: str | None = None
    monitoring: dict = field(default_factory=dict)  # the monitor's events, replans, checks
    frames: dict = field(default_factory=dict)  # each camera's last image (name -> array)
    #: The perception layer's record (empty for ``truth``): ``summary`` (summary.json's
    #: ``perception`` figures), ``rows`` (each estimate's errors), ``image`` (the first
    #: perception camera's last colour image), ``outlines`` (its estimated cubes there),
    #: ``samples`` (with ``perception.keep_points``: each sighting's points, rays and the
    #: truth: (t, cube, points, rays, position, rotation)).
    perception: dict = field(default_factory=dict)

    @property
    def rtf(self) -> float:
        return self.sim_s / self.wall_s if self.wall_s > 0 else float("inf")


def _logs(cake: CakeDiagram, context) -> Logs:
    data = {name: logger.FindLog(context) for name, logger in cake.loggers.items()}
    n = min(log.data().shape[1] for log in data.values())

    def rows(name: str) -> np.ndarray:
        return data[name].data()[:, :n]

    state, desired, labels = rows("state"), rows("desired_state"), rows("labels")
    return Logs(
        t=data["state"].sample_times()[:n],
        q=state[:7].T,
        v=state[7:14].T,
        q_d=desired[:7].T,
        v_d=desired[7:14].T,
        a_d=rows("desired_acceleration").T,
        fingers_d=rows("finger_state")[0],
        phase=labels[0].round().astype(int),
        action=labels[1].round().astype(int),
        tau_commanded=rows("tau_commanded").T,
        tau_applied=rows("tau_applied").T,
        tau_requested=rows("tau_requested").T if "tau_requested" in data else None,
        gravity=rows("gravity").T,
        fingers=rows("hand")[0] if "hand" in data else None,
    )


class ProgressBar:
    """A one-line progress bar on stderr (redrawn on a terminal, sparse lines otherwise)."""

    def __init__(
        self,
        n_actions: int,
        describe: Callable[[int], str],
        enabled: bool = True,
        unit: str = "action",
    ):
        #: ``action``: the plan's actions (a planned run); ``step``: a whole-task policy's
        #: steps, counted against its budget of ``n_actions`` steps.
        self.n = n_actions
        self.describe = describe
        self.enabled = enabled
        self.unit = unit
        self.tty = sys.stderr.isatty()
        self._last_line = -math.inf  # the first update prints: the simulation has begun

    def update(
        self, sim_t: float, wall: float, done: int, final: bool = False, note: str = ""
    ) -> None:
        """Draw the line: ``done`` actions (or policy steps) so far; ``note`` says what the
        geometric layer is doing (a learned skill's action and its steps in it), in place
        of the plan's action at ``done``."""
        if not self.enabled:
            return
        # A run that recovers executes more actions than its plan had: the bar is full
        # and the count goes on ("action 12 of 10+").
        frac = min(1.0, done / self.n) if self.n else 1.0
        bar = "#" * int(20 * frac) + "." * (20 - int(20 * frac))
        rtf = sim_t / wall if wall > 0 else 0.0
        what = self.describe(done) if done < self.n else "done"
        if self.unit == "step":
            step = f"policy step {done}/{self.n}" + (" done" if final else "")
        elif note and not final:  # the geometric layer says what it is doing
            step = f"action {done + 1}{f'/{self.n}' if done < self.n else f' of {self.n}+'} {note}"
        elif final or done < self.n:
            step = f"action {min(done + 1, self.n)}/{self.n} {what}"
        else:
            step = f"action {done + 1} of {self.n}+ (recovering)"
        line = f"simulating [{bar}] {sim_t:5.1f} s sim  RTF {rtf:5.1f}  {step}"
        if self.tty:
            print("\r" + line.ljust(100), end="\n" if final else "", file=sys.stderr, flush=True)
        elif final or wall - self._last_line >= 2.0:
            print(line, file=sys.stderr, flush=True)
            self._last_line = wall


def plugin_specs(scenario) -> dict[str, str]:
    """The scenario's plug-ins (``module:attribute``) and what each is."""
    from cake_drake.scenario import Planned

    named = [
        (scenario.task.planner, "planner"),
        (scenario.motion.ik, "IK solver"),
        (scenario.motion.planner, "motion planner"),
    ]
    if isinstance(scenario.reference, Planned):
        named.append((scenario.reference.action_source, "action source"))
    factory = getattr(scenario.controller, "factory", None)
    if factory:
        named.append((factory, "controller"))
    return {spec: what for spec, what in named if is_plugin(spec)}


def execute(
    cake: CakeDiagram,
    max_sim_s: float = 300.0,
    settle_s: float = 0.3,
    chunk_s: float = 0.05,
    progress: ProgressBar | None = None,
    moves=(),
) -> Execution:
    """Run the simulation to the end of the reference's actions (or an error, or the budget).

    ``moves`` are :class:`cake_drake.world.faults.Move` faults: at each one's time the
    cube is set down elsewhere on the table.
    """
    simulator = Simulator(cake.diagram)
    simulator.set_target_realtime_rate(cake.scenario.visualization.realtime_rate)
    context = simulator.get_mutable_context()
    plant_context = cake.scene.plant.GetMyMutableContextFromRoot(context)
    set_world_parameters(cake.scene, plant_context, cake.scenario.world, cake.scenario.seed)
    specs = plugin_specs(cake.scenario)
    step_budget = cake.scenario.simulation.step_budget_s

    def advance(to: float | None = None) -> None:
        """Simulate to ``to`` (initialize when None); what a plug-in raises inside Drake's
        callbacks comes out as one line naming it (exit 3)."""
        try:
            with budget(step_budget if specs else None):
                simulator.Initialize() if to is None else simulator.AdvanceTo(to)
        except (KeyboardInterrupt, CakeDrakeError):
            raise
        except BaseException as e:  # an exception, SystemExit, or the budget's end
            failed = raised_in_simulation(e, specs, step_budget)
            if failed is None:
                raise
            raise failed from None

    advance()
    plant = cake.scene.plant
    pending = sorted(moves, key=lambda m: m.time)
    t0 = time.perf_counter()
    t = 0.0
    while True:
        t = min(t + chunk_s, max_sim_s)
        if pending and pending[0].time <= t:
            t = pending[0].time
        advance(t)
        while pending and pending[0].time <= t:
            m = pending.pop(0)
            plant_context = plant.GetMyMutableContextFromRoot(context)
            move_cube(plant, plant_context, cake.scene.cube_body(m.cube), m.x, m.y)
        done, finished, error, warnings = cake.reference.status(context)
        if progress and progress.enabled:
            progress.update(t, time.perf_counter() - t0, done, note=cake.reference.note(context))
        if error is not None or finished or t >= max_sim_s:
            break
    if error is None and not finished:
        error = f"time budget of {max_sim_s:g} s simulated ran out after {done} actions"
    advance(context.get_time() + settle_s)
    wall = time.perf_counter() - t0
    if progress:
        progress.update(context.get_time(), wall, done, final=True)
    plant_context = cake.scene.plant.GetMyContextFromRoot(context)
    poses = cube_poses(cake.scene, plant_context)
    fingers = float(cake.scene.plant.GetPositions(plant_context, cake.scene.hand)[0])
    X_WG = cake.scene.grasp_frame.CalcPoseInWorld(plant_context)
    reading = read_facts(poses, X_WG=X_WG, finger_opening=fingers)
    return Execution(
        sim_s=context.get_time(),
        wall_s=wall,
        actions_done=done,
        n_actions=len(cake.reference.actions),
        error=error,
        poses=poses,
        reading=reading,
        offsets=stack_offsets(poses, reading.facts),
        logs=_logs(cake, context),
        warnings=warnings,
        q_final=cake.scene.plant.GetPositions(plant_context, cake.scene.arm).copy(),
        fingers_final=fingers,
        actions=cake.reference.executed(context),
        ended=getattr(cake.reference.policy, "ended", None),
        monitoring=cake.reference.monitoring(context),
        frames=grab(cake.cameras, cake.scenario.cameras, context) if cake.cameras else {},
        perception=_perception_record(cake, context),
    )


def _perception_record(cake: CakeDiagram, context) -> dict:
    """What the estimator saw and how far off it was, against the logged truth."""
    estimator = cake.estimator
    if estimator is None:
        return {}
    own = estimator.GetMyContextFromRoot(context)
    final = estimator.estimate(own)  # the last frame (a new one at the end of the run)
    belief = estimator.belief(own)
    truth = {}
    for name in cake.scene.cubes:
        log = cake.loggers[f"truth_{name}"].FindLog(context)
        truth[name] = (log.sample_times(), log.data().T)
    rows = errors(belief.log, truth)
    p = cake.scenario.perception
    summary = {
        "estimator": p.estimator,
        "cameras": [
            {
                "name": c.name,
                "width": c.width,
                "height": c.height,
                "fov_y_deg": c.fov_y_deg,
                "xyz": list(c.xyz),
                "attached_to": c.attached_to,
            }
            for c in estimator.cameras
        ],  # fmt: skip
        "noise": p.noise.model,
        **summarize(rows, belief.frames, final.unseen()),
    }
    samples = [
        (t, name, P, rays, *truth_at(truth, name, t)) for t, name, P, rays in belief.points
    ] if belief.points is not None else None  # fmt: skip
    first = estimator.cameras[0]
    sensor = cake.diagram.GetSubsystemByName(f"perception_camera_{first.name}")
    image = sensor.color_image_output_port().Eval(sensor.GetMyContextFromRoot(context)).data
    estimates = {n: e.X_WB for n, e in final.cubes.items() if e.X_WB is not None}
    return {"summary": summary, "rows": rows, "image": np.array(image[:, :, :3]),
            "camera": first, "estimates": estimates, "samples": samples}  # fmt: skip
