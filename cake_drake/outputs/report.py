"""Everything a run writes: plan, trajectory, pictures, plots and the summary."""

from __future__ import annotations

import shutil
import time

import numpy as np
from pydrake.math import RollPitchYaw

from cake_drake.dynamic.controllers import TORQUE_LIMITS
from cake_drake.errors import InputError, OutputError
from cake_drake.formats import save_npz
from cake_drake.outputs.files import OutputDir
from cake_drake.outputs.replay import write_replay
from cake_drake.outputs.worker import OutputWorker
from cake_drake.perception.learned import checkpoint_of, describe, is_learned
from cake_drake.scenario import dump_scenario
from cake_drake.symbolic import fact_str, write_plan
from cake_drake.world.cameras import renderer_in_use


def gravity_torques(control_plant, q: np.ndarray) -> np.ndarray:
    """g(q) of the 7-DOF control plant at each row of ``q`` (the static torque term)."""
    context = control_plant.CreateDefaultContext()
    out = np.empty_like(q)
    for i, qi in enumerate(q):
        control_plant.SetPositions(context, qi)
        out[i] = -control_plant.CalcGravityGeneralizedForces(context)
    return out


def trajectory_samples(cake, execution) -> tuple[dict[str, np.ndarray], list[str]]:
    """The reference the controller followed, sampled at the simulation step."""
    logs = execution.logs
    samples = {
        "t": logs.t,
        "q": logs.q_d,
        "qd": logs.v_d,
        "qdd": logs.a_d,
        "gripper": logs.fingers_d,
        "phase": logs.phase.astype(np.int16),
        "action": logs.action.astype(np.int16),
    }
    return samples, list(execution.actions)


def layers(scenario, plan) -> dict:
    """Each layer of the cake, classical (which one) or learned (which checkpoint): the
    label the chapter asks a student to put on every layer of a system."""
    from cake_drake.paths import resolve_path
    from cake_drake.plugins import load_attribute
    from cake_drake.scenario import CHECKPOINT_DESCRIBE, SKILL_DESCRIBE, Policy, Recorded
    from cake_drake.symbolic.learned import is_learned

    reference, motion = scenario.reference, scenario.motion
    if isinstance(reference, Policy):
        what = reference.checkpoint or reference.factory
        how = ""
        if reference.checkpoint:  # what learned it, said by the learned layer's adapter
            describe = load_attribute(CHECKPOINT_DESCRIBE, "policy")
            how = f", {describe(resolve_path(reference.checkpoint))}"
        policy = {"kind": "learned", "what": f"whole-task policy{how} ({what})"}
        symbolic = geometric = policy
    else:
        planner = getattr(plan, "planner", None)
        if isinstance(planner, str) and is_learned(planner):
            symbolic = {"kind": "learned", "what": f"{planner}, {plan.heuristic}"}
        else:
            symbolic = {"kind": "classical", "what": planner}
        if isinstance(reference, Recorded):
            geometric = {"kind": "classical", "what": f"a recorded trajectory ({reference.path})"}
        elif motion.skills:  # what the skills read and answer, said by their adapter
            describe = load_attribute(SKILL_DESCRIBE, "skill")
            how = describe(resolve_path(motion.skills))
            rules = list(motion.skill_rules)
            shield = f"shield of {len(rules)} steps" if rules else "the network alone, no shield"
            what = f"skills, {how}, {shield} ({motion.skills})"
            geometric = {"kind": "learned", "what": what, "shield": rules}
        else:
            moves = f"waypoints, IK ({motion.ik}), {motion.planner} moves"
            geometric = {"kind": "classical", "what": moves}
    residual = getattr(scenario.controller, "residual", "")
    if residual:
        dynamic = {"kind": "learned", "what": f"residual on computed torque ({residual})"}
    else:
        c = scenario.controller
        kind = type(c).__name__
        name = (
            {
                "ComputedTorque": "computed torque, InverseDynamicsController",
                "JointPd": "joint PD",
                "Pid": "PID",
            }.get(kind)
            or getattr(c, "factory", "")
            or kind
        )
        dynamic = {"kind": "classical", "what": name}
    return {
        "symbolic": symbolic,
        "geometric": geometric,
        "dynamic": dynamic,
        "perception": perception_layer(scenario.perception),
    }


def perception_layer(perception) -> dict:
    """The cake's base: where its knowledge of the cubes comes from."""
    if perception.estimator == "truth":
        return {"kind": "truth", "what": "the simulator's own poses, no camera (truth)"}
    views = perception.views()
    cams = ", ".join(f"{c.name} {c.width}x{c.height}" for c in views)
    noise = ", depth noise" if perception.noise.model != "off" else ""
    if is_learned(perception.estimator):
        what = describe(checkpoint_of(perception.estimator))
        return {"kind": "learned", "what": f"{what}: depth points found by colour, no ICP; "
                f"cameras {cams}{noise}"}  # fmt: skip
    how = {
        "depth": "cubes found by colour, fitted to depth points (footprint start, ICP)",
        "oracle": "cubes found by the renderer's labels (ground truth), fitted to depth points",
    }[perception.estimator]
    return {"kind": "classical", "what": f"{perception.estimator}: {how}; cameras {cams}{noise}"}


def cake_title(problem, cake) -> str:
    """The cake picture's title: the problem and the controller."""
    return f"the cake of this run: {problem.name}, {cake.controller.name} controller"


def layers_line(found: dict) -> str:
    """:func:`layers` in one line: ``layers: symbolic classical (astar-lmcut) · ...``."""
    return "layers: " + " · ".join(
        f"{name} {layer['kind']} ({layer['what']})" for name, layer in found.items()
    )


def summary(result) -> dict:
    """The content of ``summary.json`` for a :class:`cake_drake.pipeline.RunResult`."""
    plan, cake, execution, stages = result.plan, result.cake, result.execution, result.stages
    problem, scenario, controller = result.problem, cake.scenario, cake.controller
    logs = execution.logs
    blocks = {
        name: {
            "position": np.round(X.translation(), 5).tolist(),
            "rpy": np.round(RollPitchYaw(X.rotation()).vector(), 5).tolist(),
        }
        for name, X in sorted(execution.poses.items())
    }
    wall = sum(v for k, v in stages.items() if k != "ik")  # IK runs inside the simulation
    return {
        "success": result.success,
        "message": result.message,
        "mode": controller.name,
        "controller": {
            "name": controller.name,
            "gains": _gains(controller),
        },
        "layers": layers(scenario, result.plan),
        "perception": execution.perception.get("summary") or {"estimator": "truth"},
        "ik": scenario.motion.ik if cake.ik is not None else None,
        "reference": getattr(scenario.reference, "path", None),
        "scenario": "scenario.yaml",
        "problem": problem.problem_path,
        "goal": [fact_str(f) for f in sorted(problem.goal)],
        "plan": [str(a) for a in plan.actions],
        "planner": {
            "name": plan.planner,
            "search": plan.search,
            "heuristic": plan.heuristic,
            "optimal": plan.optimal,
            "time_s": round(plan.time_s, 4),
        },
        "actions_done": execution.actions_done,
        "executed": list(execution.actions),
        "replans": execution.monitoring.get("replans", 0),
        "repeats": sum(e.get("kind") == "repeat" for e in execution.monitoring.get("events", [])),
        "skills": execution.monitoring.get("skills"),
        "faults": [{"kind": type(f).__name__, **vars(f)} for f in result.faults],
        "events": execution.monitoring.get("events", []),
        "error": execution.error,
        "collisions": list(execution.warnings),
        "blocks": blocks,
        "facts": [fact_str(f) for f in sorted(execution.reading.facts)],
        "unclassified": list(execution.reading.problems),
        "stack_offsets_mm": {k: round(v * 1000, 2) for k, v in sorted(execution.offsets.items())},
        # Each stack as it landed, off the cube below (the monitor's, when its action ended).
        "places": execution.monitoring.get("places", []),
        "sim_s": round(execution.sim_s, 3),
        "wall_s": round(wall, 3),
        "simulation_wall_s": round(execution.wall_s, 3),
        "rtf": round(execution.rtf, 2),
        "stages_s": {k: round(v, 4) for k, v in stages.items()},
        "tracking_error": logs.tracking_error(),
        "torque_saturation": logs.saturation(TORQUE_LIMITS),
        "ik_solves": len(cake.ik.times_ms) if cake.ik else 0,
        "ik_median_ms": round(float(np.median(cake.ik.times_ms)), 3)
        if cake.ik and cake.ik.times_ms
        else None,
        "policy": _policy(cake.reference.policy),
        "motion_planner": _motion_planner(scenario, cake.reference.geometric),
        # The GL implementation the cameras were rendered with (a GPU, or llvmpipe).
        "renderer": renderer_in_use() if cake.cameras else None,
    }


def _motion_planner(scenario, waypoint_ik) -> dict | None:
    """The motion planner's queries (blocked moves only): how many, how long, how much
    longer than the blocked straight line; None for a run that does not plan motion."""
    planning = getattr(waypoint_ik, "planning", None)
    if planning is None:
        return None
    ms = [q[2] for q in planning.queries]
    ratios = [q[3] for q in planning.queries if q[3] is not None]
    return {
        "name": scenario.motion.planner,
        "queries": len(ms),
        "failed": sum(q[3] is None for q in planning.queries),
        "median_ms": round(float(np.median(ms)), 2) if ms else None,
        "p90_ms": round(float(np.percentile(ms, 90)), 2) if ms else None,
        "path_over_straight": round(float(np.median(ratios)), 3) if ratios else None,
        "collision_checks": planning.space.checks,
        "padding_m": planning.space.padding,
    }


def _policy(source) -> dict | None:
    """A policy run's steps, and the actions clipped to their bounds or out of reach."""
    if source is None:
        return None
    c = source.counts
    return {
        "factory": source.label,
        "action_space": source.space,
        "steps": c.steps,
        "clipped": c.clipped,
        "unreachable": c.unreachable,
        "said_done": source.done and c.steps < source.max_steps,
        "max_steps": source.max_steps,
        "ended": source.ended,
    }


def fault_marks(faults, logs) -> list[tuple[float, str]]:
    """(time, label) of each fault that struck: a knock's or a move's time, and for a
    slip the start of the action it struck (when that action ran)."""
    marks = []
    for f in faults:
        kind = type(f).__name__.lower()
        if hasattr(f, "time"):
            marks.append((float(f.time), f"{kind} {f.cube}"))
        elif hasattr(f, "action"):
            rows = np.flatnonzero(np.asarray(logs.action) == f.action - 1)
            if len(rows):
                marks.append((float(logs.t[rows[0]]), f"{kind} (action {f.action})"))
    return marks


def _gains(controller) -> dict | None:
    """Per-joint gains of a controller that has them (the shipped ones do)."""
    gains = getattr(controller, "gains", None)
    if gains is None:
        return None
    kp, kd = gains()
    return {"kp": np.asarray(kp).tolist(), "kd": np.asarray(kd).tolist()}


def write_outputs(
    out: OutputDir,
    result,
    worker: OutputWorker,
    render: bool = True,
    meshcat=None,
) -> None:
    """Stage every output file in ``out`` (the caller commits or discards).

    The picture and the joint plot go to ``worker`` first, so they are drawn while the
    plan, trajectory and summary are written here. Adds ``stages["outputs"]``: the time
    spent here before the summary is written.
    """
    t0 = time.perf_counter()
    plan, cake, execution, stages = result.plan, result.cake, result.execution, result.stages
    logs = execution.logs
    if render:
        worker.submit_render(
            execution.poses, execution.q_final, execution.fingers_final, out.path("final_state.png")
        )
    controller = cake.controller
    # With the plant's built-in PD the torque that acts is the net actuation; otherwise
    # it is what the controller commands.
    torque_mode = controller.arm_pd_gains() is None
    gains = _gains(controller)
    worker.submit_plot(
        t=logs.t,
        q=logs.q,
        q_d=logs.q_d,
        tau=logs.tau_commanded if torque_mode else logs.tau_applied,
        phase=logs.phase,
        path=out.path("joint4_torque.png"),
        title=f"joint 4 (elbow), {controller.name} controller"
        + (f", Kp={gains['kp'][3]:g} Kd={gains['kd'][3]:g}" if torque_mode and gains else ""),
        tau_label="τ commanded" if torque_mode else "τ applied",
        extra_tau=[(logs.gravity, "g(q): static gravity term")],
        marks=[(e["time_s"], e["kind"]) for e in execution.monitoring.get("events", [])],
        faults=fault_marks(result.faults, logs),
    )
    if not worker.cake_asked:  # not asked for while the world was simulated
        worker.submit_cake(layers(cake.scenario, plan), cake_title(result.problem, cake))
    try:
        write_plan(plan, out.path("plan.txt"))
        out.write_text("scenario.yaml", dump_scenario(cake.scenario))
        samples, actions = trajectory_samples(cake, execution)
        save_npz(out.path("trajectory.npz"), samples, actions)
        if cake.scenario.outputs.logs:
            arrays = {k: v for k, v in vars(logs).items() if isinstance(v, np.ndarray)}
            np.savez_compressed(out.path("logs.npz"), **arrays)
    except (OSError, InputError) as e:
        raise OutputError(f"{out.out}: cannot write the outputs ({e})") from None
    if execution.perception:
        from cake_drake.outputs.perception import write_perception_figure

        write_perception_figure(execution.perception, out.path("perception.png"))
    for name, image in execution.frames.items():
        from cake_drake.world.render import save_png

        if image.ndim == 3:  # a colour image (depth images are left to the caller)
            rgba = np.dstack([image, np.full(image.shape[:2], 255, np.uint8)])
            save_png(rgba, out.path(f"camera_{name}.png"))
    if meshcat is not None:
        try:
            write_replay(meshcat, out.path("replay.html"))
        except OSError as e:
            raise OutputError(f"{out.out}: cannot write replay.html ({e})") from None
    try:
        worker.wait()
    except RuntimeError as e:
        raise OutputError(f"{out.out}: {e}") from None
    try:
        shutil.copyfile(worker.cake(), out.path("cake.png"))
    except (OSError, TypeError) as e:  # TypeError: the helper wrote no cake
        raise OutputError(f"{out.out}: cannot write cake.png ({e})") from None
    stages["outputs"] = time.perf_counter() - t0
    out.write_json("summary.json", summary(result))
