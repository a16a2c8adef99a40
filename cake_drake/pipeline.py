"""The whole cake as a library call: ``run(scenario) -> RunResult``.

:func:`check` is the one validation pass: it reads every input a scenario names (PDDL,
plan file, recorded reference), resolves every plug-in and checks every number, and
refuses bad input with one :class:`~cake_drake.errors.InputError` line before anything is
planned, built or simulated. :func:`run` then plans (or reads the plan), builds the
Diagram, simulates, reads the verdict from the measured poses and writes the outputs,
including the resolved ``scenario.yaml`` that reproduces the run.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

from cake_drake.diagram import CakeDiagram, build_diagram
from cake_drake.dynamic.controllers import per_joint
from cake_drake.errors import InputError, NoPlanError
from cake_drake.execution import Execution, ProgressBar, execute
from cake_drake.outputs.files import check_output_folder
from cake_drake.perception.settings import check_perception
from cake_drake.plugins import PluginError, is_plugin, load_attribute, resolve
from cake_drake.policy.shield import check_names as check_shield_steps
from cake_drake.scenario import (
    CHECKPOINT_CHECK,
    CHECKPOINT_POLICY,
    HELPER_CHOICES,
    SKILL_CHECK,
    Generate,
    Policy,
    Recorded,
    Scenario,
    portable_path,
    resolve_path,
)
from cake_drake.symbolic import (
    DEFAULT_PLANNER,
    NAMINGS,
    PLANNERS,
    PROBLEM_5_OPTIMAL_LENGTH,
    GroundAction,
    Plan,
    Problem,
    check_state,
    fact_str,
    load_domain,
    load_problem,
    parse_problem,
    random_problem,
    read_plan,
    solve_problem,
    towers,
    validate_plan,
)
from cake_drake.symbolic.learned import PREFIX as LEARNED_PREFIX
from cake_drake.symbolic.learned import checkpoint_of, is_learned, load_planner
from cake_drake.symbolic.planners import overran_time_limit
from cake_drake.symbolic.roles import blocksworld_view
from cake_drake.world.cameras import check_cameras
from cake_drake.world.facts import STACK_TOL, read_goal
from cake_drake.world.faults import Move, RandomFault, Slip, check_faults, resolve_random
from cake_drake.world.scene import jittered, layout

#: A planner: ``(problem, time_limit) -> Plan`` (or a sequence of ground actions).
Planner = Callable[[Problem, float | None], "Plan | Sequence[GroundAction]"]


def _registered(name: str) -> Planner:
    return partial(lambda problem, time_limit, _n: solve_problem(problem, _n, time_limit), _n=name)


class _PlannerRegistry(Mapping):
    """The shipped planners by name, and ``learned@DIR`` for any learned checkpoint (checked
    when the scenario is: a missing or damaged folder is one line before anything runs)."""

    def __getitem__(self, name: str) -> Planner:
        if not isinstance(name, str) or not (name in PLANNERS or is_learned(name)):
            raise KeyError(name)
        if is_learned(name):
            load_planner(checkpoint_of(name))
        return _registered(name)

    def __iter__(self):
        return iter([*PLANNERS, f"{LEARNED_PREFIX}DIR"])

    def __len__(self) -> int:
        return len(PLANNERS) + 1


#: The shipped planners, through the same door as a user's ``module:attribute``.
PLANNER_REGISTRY: Mapping[str, Planner] = _PlannerRegistry()


@dataclass
class Checked:
    """What :func:`check` read and resolved, ready to run."""

    scenario: Scenario
    problem: Problem
    planner: Planner | None  # None when a plan file is executed
    out: Path | None
    generated: str | None = None  # the PDDL text of task.generate, saved as problem.pddl


@dataclass
class RunResult:
    """What a run produced, for the CLI, the benchmarks, the sweeps and the notebooks."""

    success: bool
    message: str
    plan: Plan
    execution: Execution
    cake: CakeDiagram
    problem: Problem
    stages: dict[str, float] = field(default_factory=dict)
    written: list[Path] = field(default_factory=list)
    unmet: list[str] = field(default_factory=list)
    faults: list = field(default_factory=list)  # the faults as they happened (seeds resolved)


def _range(value: float, lo: float, hi: float, what: str, unit: str = "") -> None:
    number = isinstance(value, int | float) and not isinstance(value, bool)
    if not (number and lo <= value <= hi and (isinstance(value, int) or math.isfinite(value))):
        shown = repr(value) if len(repr(value)) <= 24 else repr(value)[:20] + "..."
        raise InputError(f"{what} = {shown} is outside {lo:g} to {hi:g}{unit}")


def _check_numbers(s: Scenario) -> None:
    w, m, sim = s.world, s.motion, s.simulation
    _range(w.time_step, 0.0005, 0.02, "world.time_step", " s")
    _range(w.slot_radius, 0.2, 2.0, "world.slot_radius", " m")
    _range(w.slot_spacing, 0.05, 1.0, "world.slot_spacing", " m")
    _range(w.slot_spacing_max, 0.05, 1.0, "world.slot_spacing_max", " m")
    _range(w.placement.xy, 0.0, 0.03, "world.placement.xy", " m")
    _range(w.placement.yaw_deg, 0.0, 45.0, "world.placement.yaw_deg", " degrees")
    _range(w.sap_near_rigid_threshold, 0.0, 1.0, "world.sap_near_rigid_threshold")
    _range(w.finger_kp, 1e-3, 1e6, "world.finger_kp", " N/m")
    _range(w.finger_kd, 0.0, 1e5, "world.finger_kd", " N s/m")
    _range(w.cube_mass_kg, 0.01, 1.0, "world.cube_mass_kg", " kg")
    if w.cube_mass_range_kg:
        where = "world.cube_mass_range_kg"
        if len(w.cube_mass_range_kg) != 2:
            raise InputError(
                f"{where} has {len(w.cube_mass_range_kg)} numbers; give two, [lo, hi] kg"
            )
        for mass in w.cube_mass_range_kg:
            _range(mass, 0.01, 1.0, where, " kg")
        if w.cube_mass_range_kg[0] > w.cube_mass_range_kg[1]:
            raise InputError(
                f"{where} = {list(w.cube_mass_range_kg)}: lo above hi; give [lo, hi] kg"
            )
    _range(w.payload_kg, 0.0, 2.0, "world.payload_kg", " kg")
    for f in per_joint(w.joint_friction, "world.joint_friction"):
        _range(f, 0.0, 5.0, "world.joint_friction", " N m s/rad")
    approximations = ("sap", "lagged", "similar", "tamsi")
    if w.contact_approximation not in approximations:
        raise InputError(
            f"world.contact_approximation {w.contact_approximation!r}; choose one of: "
            + ", ".join(approximations)
        )
    t = m.timing
    _range(t.velocity_fraction, 0.01, 1.0, "motion.timing.velocity_fraction")
    _range(t.acceleration_fraction, 0.01, 1.0, "motion.timing.acceleration_fraction")
    _range(t.gentle, 0.01, 1.0, "motion.timing.gentle")
    _range(t.blend, 0.0, 0.5, "motion.timing.blend")
    _range(t.min_move, 0.0, 10.0, "motion.timing.min_move", " s")
    _range(t.gripper_time, 0.01, 10.0, "motion.timing.gripper_time", " s")
    _range(t.settle_time, 0.0, 10.0, "motion.timing.settle_time", " s")
    wp = m.waypoints
    _range(wp.approach, 0.0, 0.5, "motion.waypoints.approach", " m")
    _range(wp.transit_clearance, 0.0, 0.5, "motion.waypoints.transit_clearance", " m")
    _range(wp.place_drop, 0.0, 0.05, "motion.waypoints.place_drop", " m")
    _range(wp.release_height, 0.0, 0.05, "motion.waypoints.release_height", " m")
    _range(wp.slot_clearance, 0.0, 0.5, "motion.waypoints.slot_clearance", " m")
    if m.avoid_collisions and m.planner != "straight":
        raise InputError(
            f"motion.avoid_collisions and motion.planner {m.planner} both given: the planner "
            "already chooses motions that hit nothing; drop one"
        )
    if m.avoid_collisions and not m.collision_check:
        raise InputError(
            "motion.avoid_collisions needs motion.collision_check (--avoid-collisions "
            "cannot go with --no-collision-check)"
        )
    if s.outputs.helpers not in HELPER_CHOICES:
        raise InputError(
            f"outputs.helpers {s.outputs.helpers!r}; choose one of: " + ", ".join(HELPER_CHOICES)
        )
    _range(s.visualization.realtime_rate, 0.0, 100.0, "visualization.realtime_rate")
    _range(sim.settle_s, 0.0, 60.0, "simulation.settle_s", " s")
    _range(sim.max_sim_s, 1.0, 3600.0, "simulation.max_sim_s", " s")
    _range(sim.step_budget_s, 0.1, 3600.0, "simulation.step_budget_s", " s")
    if s.task.time_limit is not None:
        _range(s.task.time_limit, 1e-3, 86400.0, "task.time_limit", " s")
    g = s.task.generate
    if g is not None:  # bounded before anything is generated
        _range(g.blocks, 1, MAX_GENERATED_BLOCKS, "task.generate.blocks")
        for name in ("max_height", "goal_max_height"):
            value = getattr(g, name)
            if value is not None:
                _range(value, 1, MAX_GENERATED_BLOCKS, f"task.generate.{name}")
    _range(s.seed, -(2**63), 2**63 - 1, "seed")


#: The most blocks a generated problem may have: the planners answer 30 blocks in seconds,
#: and no table of the world's slots holds their towers beyond that.
MAX_GENERATED_BLOCKS = 30


def generated_problem(g: Generate) -> str:
    """The PDDL text ``task.generate`` describes (the same fields always give the same text)."""
    if g.style not in NAMINGS:
        raise InputError(f"task.generate.style {g.style!r}; choose one of: {', '.join(NAMINGS)}")
    try:
        return random_problem(
            g.blocks,
            g.seed,
            g.style,
            tall=g.tall,
            max_height=g.max_height,
            goal_max_height=g.goal_max_height,
            partial=g.partial,
        )
    except InputError as e:
        raise InputError(f"task.generate: {e}") from None


def load_world_problem(domain: Path, problem_path: Path | str, text: str | None = None) -> Problem:
    """A Blocksworld problem (any naming: its domain is read by structure) whose initial
    state the world can lay out; refused with one line (exit 2) otherwise. With ``text``
    the problem is that PDDL (``problem_path`` only names it in messages)."""
    if text is None:
        problem = load_problem(domain, problem_path)
    else:
        problem = parse_problem(load_domain(domain), text, str(problem_path))
    view = blocksworld_view(problem)  # refuses a domain the robot cannot execute
    issues = check_state(problem.init, view.blocks, vocabulary=view.roles.vocabulary)
    if issues:
        raise InputError(f"{problem_path}: the initial state cannot be laid out: {issues[0]}")
    held = [f for f in view.init if f[0] == "holding"]
    if held:
        raise InputError(
            f"{problem_path}: the initial state has a block in the hand "
            f"({fact_str(next(iter(view.roles.from_canonical(held))))}); the world starts "
            "with every block on the table or on another block"
        )
    return problem


def check(scenario: Scenario, write: bool = True) -> Checked:
    """The one validation pass: every input read, every plug-in resolved, every number
    checked, before anything is planned or simulated."""
    from cake_drake.dynamic.controllers import make_controller
    from cake_drake.dynamic.reference import ReferenceTrajectory
    from cake_drake.geometric.ik import SOLVERS
    from cake_drake.geometric.planners import make_planner
    from cake_drake.systems import ACTION_SOURCES

    s = scenario
    _check_numbers(s)
    check_cameras(s.cameras)
    check_perception(s.perception)
    getattr(s.controller, "check", lambda: None)()
    make_controller(s.controller)
    task = s.task
    generated = None
    if task.generate is None:
        problem = load_world_problem(resolve_path(task.domain), resolve_path(task.problem))
    else:
        generated = generated_problem(task.generate)
        try:
            problem = load_world_problem(resolve_path(task.domain), "task.generate", generated)
        except InputError as e:
            style_domain = portable_path(NAMINGS[task.generate.style].domain_file)
            raise InputError(
                f"{e} (task.generate.style {task.generate.style} writes problems for "
                f"{style_domain}; task.domain is {task.domain})"
            ) from None
    view = blocksworld_view(problem)
    layout(towers(view.init), s.world.slots)
    planner = None
    if task.plan:
        if task.planner != DEFAULT_PLANNER:
            raise InputError(
                f"task.plan and task.planner ({task.planner}) both given: a plan file is "
                "executed as it is, not planned; drop one"
            )
        plan_path = resolve_path(task.plan)
        if not plan_path.is_file():
            raise InputError(f"{plan_path}: no such plan file")
    else:
        planner = resolve(
            task.planner, PLANNER_REGISTRY, "planner", budget=lambda problem, limit: limit
        )
    check_skill_settings(s.motion)
    if isinstance(s.reference, Recorded):
        if not s.reference.path:
            raise InputError("reference: !Recorded needs a path (a trajectory.npz from a run)")
        replay = ReferenceTrajectory.from_npz(
            resolve_path(s.reference.path), s.reference.differentiate
        )
        if replay.end_time > s.simulation.max_sim_s:
            raise InputError(
                f"{s.reference.path}: the recording lasts {replay.end_time:g} s, more than "
                f"simulation.max_sim_s = {s.simulation.max_sim_s:g} s"
            )
    elif isinstance(s.reference, Policy):
        if s.motion.skills:
            raise InputError(
                f"motion.skills ({s.motion.skills}) with reference: !Policy: a whole-task "
                "policy replaces the geometric layer the skills would be; keep one of the two"
            )
        check_policy(s.reference, s.cameras)
    else:
        resolve(s.reference.action_source, ACTION_SOURCES, "action source")
        resolve(s.motion.ik, SOLVERS, "IK solver")
        make_planner(s.motion.planner)
        if s.motion.skills:
            check_skills(s.motion)
    view = blocksworld_view(problem)
    check_faults([f for f in s.faults if not isinstance(f, Slip)], view.blocks, n_actions=1 << 30)
    out = Path(s.outputs.folder) if write else None
    if out is not None:
        check_output_folder(out, "run", run_outputs(s, generated), run_inputs(s))
    return Checked(s, problem, planner, out, generated)


def check_skill_settings(motion) -> None:
    """The learned skills' settings, checked whether or not ``motion.skills`` names a
    checkpoint: every number of a scenario is checked before any work, read or not."""
    if motion.skill_action_space not in ("", "joint_position", "ee_delta", "relative"):
        raise InputError(
            f"motion.skill_action_space: {motion.skill_action_space!r}; one of joint_position, "
            "ee_delta, relative (a skill that never sees the arm), or empty (the skill's own)"
        )
    _range(motion.skill_rate_hz, 0.5, 100.0, "motion.skill_rate_hz", " Hz")
    _range(motion.skill_smooth_s, 0.0, 5.0, "motion.skill_smooth_s", " s")
    _range(motion.skill_ensemble, 0.0, 10.0, "motion.skill_ensemble")
    _range(motion.skill_max_steps, 0, 1_000_000, "motion.skill_max_steps")
    try:
        check_shield_steps(motion.skill_rules)
    except ValueError as e:
        raise InputError(str(e)) from None


def check_skills(motion) -> None:
    """A learned geometric layer that can run (its numbers are checked by
    :func:`check_skill_settings`): a skill checkpoint (not a whole-task policy) of the
    action space asked for, where it can run."""
    check_folder = load_attribute(SKILL_CHECK, "skill")
    if motion.skill_ensemble > 0 and motion.skill_device not in ("cpu", "auto"):
        raise InputError(
            f"motion.skill_ensemble = {motion.skill_ensemble:g} with skill_device "
            f"{motion.skill_device}: the ensembled skill acts in NumPy on the CPU; set "
            "skill_device: cpu, or skill_ensemble: 0"
        )
    check_folder(resolve_path(motion.skills), motion.skill_device, motion.skill_action_space)


def check_policy(ref: Policy, cameras=()) -> None:
    """A ``!Policy`` reference that can run: a factory that imports, a known action space,
    a rate and a step budget in range, a checkpoint that sees only ``cameras`` (the
    policy itself is built with the Diagram)."""
    from cake_drake.policy.spaces import check_space

    if ref.checkpoint:
        if ref.factory:
            raise InputError(
                f"reference: !Policy has a factory ({ref.factory}) and a checkpoint "
                f"({ref.checkpoint}): a policy is one or the other; drop one"
            )
        # The learned layer's adapter, through the plug-in door (nothing here imports it).
        load_attribute(CHECKPOINT_POLICY, "policy")
        check_folder = load_attribute(CHECKPOINT_CHECK, "policy")
        check_folder(resolve_path(ref.checkpoint), ref.action_space, ref.device, cameras)
    elif not ref.factory:
        raise InputError(
            "reference: !Policy needs a factory (module:attribute, "
            "e.g. examples.expert_policy:make) or a checkpoint (a folder from cake_drake.train)"
        )
    elif not is_plugin(ref.factory):
        raise InputError(
            f"reference.factory {ref.factory!r}: a policy is module:attribute of your own "
            "(e.g. examples.expert_policy:make)"
        )
    else:
        resolve(ref.factory, {}, "policy")
    check_space(ref.action_space, ref.options)
    _range(ref.rate_hz, 0.5, 100.0, "reference.rate_hz", " Hz")
    _range(ref.max_steps, 0, 1_000_000, "reference.max_steps")
    _range(ref.act_budget_s, 0.1, 3600.0, "reference.act_budget_s", " s")
    _range(ref.smooth_s, 0.0, 5.0, "reference.smooth_s", " s")


#: Every file a run may write to its output folder.
RUN_OUTPUTS = (
    "plan.txt", "trajectory.npz", "final_state.png", "joint4_torque.png", "cake.png",
    "summary.json", "scenario.yaml",
)  # fmt: skip


def run_outputs(s: Scenario, generated: str | None) -> set[str]:
    """The names this scenario's run writes (the optional ones only when it will)."""
    names = set(RUN_OUTPUTS)
    if generated is not None:
        names.add("problem.pddl")
    if s.visualization.meshcat:
        names.add("replay.html")
    if s.outputs.logs:
        names.add("logs.npz")
    names |= {f"camera_{c.name}.png" for c in s.cameras}
    if s.perception.estimator != "truth":
        names.add("perception.png")
    return names


def run_inputs(s: Scenario) -> list[Path]:
    """The files a run reads: none may be among the outputs it replaces."""
    paths = [s.task.domain]
    if s.task.generate is None:
        paths.append(s.task.problem)
    if s.task.plan:
        paths.append(s.task.plan)
    if isinstance(s.reference, Recorded) and s.reference.path:
        paths.append(s.reference.path)
    return [resolve_path(p) for p in paths]


#: Expected simulated seconds per action, to draw a random fault's time within the run.
SECONDS_PER_ACTION = 1.9


def resolve_faults(faults, blocks, n_actions: int, seed: int = 0, slots=()) -> list:
    """The scenario's faults with seeds drawn, checked against the plan (before simulating)."""
    out = [
        resolve_random(f, blocks, n_actions, SECONDS_PER_ACTION * n_actions, seed, slots)
        if isinstance(f, RandomFault)
        else f
        for f in faults
    ]
    check_faults(out, blocks, n_actions)
    return out


def get_plan(checked: Checked) -> Plan:
    """Plan with the scenario's planner, or read and validate its plan file."""
    task, problem = checked.scenario.task, checked.problem
    if checked.planner is None:
        plan_path = resolve_path(task.plan)
        actions = read_plan(plan_path)
        label = f"file {plan_path}"
    else:
        return call_planner(checked.planner, task.planner, problem, task.time_limit)
    return checked_plan(problem, actions, label)


def call_planner(planner: Planner, spec: str, problem: Problem, time_limit: float | None) -> Plan:
    """Plan with ``planner`` (resolved from ``spec``); what a plug-in returns is checked: a
    :class:`Plan`, a sequence of ground actions, or None for no plan. A plug-in that overruns
    the time limit (its budget) has given up, as a built-in planner does at its limit."""
    try:
        result = planner(problem, time_limit)
    except PluginError as e:
        if e.overran is None or time_limit is None:
            raise
        raise overran_time_limit(problem, spec, time_limit, e.where) from None
    if isinstance(result, Plan):
        if is_plugin(spec):
            checked_plan(problem, result.actions, spec)
        return result
    if result is None:
        raise NoPlanError(f"planner {spec} returned no plan")
    try:
        actions = tuple(result)
    except TypeError:
        actions = None
    if actions is None or not all(isinstance(a, GroundAction) for a in actions):
        shown = (
            type(result).__name__
            if actions is None
            else (
                f"a {type(result).__name__} holding "
                + ", ".join(sorted({type(a).__name__ for a in actions}))
            )
        )
        raise PluginError(
            f"planner {spec!r} returned {shown}; a planner returns a Plan, a sequence of "
            "GroundAction (cake_drake.symbolic), or None for no plan"
        )
    return checked_plan(problem, actions, spec)


def checked_plan(problem: Problem, actions: tuple[GroundAction, ...], label: str) -> Plan:
    """The plan of ``actions`` once validated against ``problem`` (exit 1 if not valid)."""
    verdict_ = validate_plan(problem, actions)
    if not verdict_.ok:
        raise NoPlanError(
            f"{label}: not a valid plan for {problem.problem_path}: {verdict_.message}"
        )
    return Plan(tuple(actions), label, "-", "-", 0.0, False)


def plan_and_layout(checked: Checked) -> tuple[Plan, tuple, dict]:
    """The plan, the table slots it needs (as many as it needs, as far apart as the arc
    allows) and the cubes' initial poses on them."""
    plan = get_plan(checked)
    scenario = checked.scenario
    needed = check_table_room(checked.problem, plan.actions, len(scenario.world.slots))
    slots = scenario.world.slots_for(needed)
    stacks = towers(blocksworld_view(checked.problem).init)
    initial = layout(stacks, slots)
    world = scenario.world
    initial = jittered(initial, stacks, world.placement, scenario.seed, world.slot_spacing)
    return plan, slots, initial


def check_table_room(problem: Problem, actions: Sequence[GroundAction], slots: int) -> int:
    """How many table slots the plan needs at once; refused if more than ``slots``.

    Every block on the table stands on a slot of its own, so the initial state and each
    put-down must find one free; checked on the plan, before anything is simulated.
    """
    view = blocksworld_view(problem)
    on_table = sum(1 for f in view.init if f[0] == "on-table")
    most = on_table
    for k, action in enumerate(actions, start=1):
        meaning = view.roles.classify(action).canonical().name
        on_table += {"pick-up": -1, "put-down": 1}.get(meaning, 0)
        most = max(most, on_table)
        if on_table > slots:
            raise InputError(
                f"the plan puts {on_table} blocks on the table at once (action {k} "
                f"{action}), but the table holds {slots} slots on the arm's arc "
                "(world.slot_radius, world.slot_spacing)"
            )
    return most


def verdict(problem: Problem, execution: Execution) -> tuple[bool, list[str], str]:
    """(success, unmet goal facts, one-line message), from the measured poses.

    The world reads facts back in the canonical names; the goal is compared in them and
    unmet facts are named in the domain's own vocabulary.
    """
    if execution.error is not None:
        return False, [], execution.error
    view = blocksworld_view(problem)
    goal = read_goal(execution.poses, view.goal, reading=execution.reading)
    unmet = [fact_str(f) for f in sorted(view.roles.from_canonical(goal.missing))]
    loose = [
        f"{b} stands {off * 1000:.1f} mm off the cube below (tolerance {STACK_TOL * 1000:.0f} mm)"
        for b, off in sorted(goal.loose.items())
    ]
    if unmet or loose:
        parts = [execution.ended] if execution.ended else []
        if unmet:
            parts.append("goal facts not true in the simulated world: " + " ".join(unmet))
        if loose:
            parts.append("; ".join(loose))
        if execution.reading.problems:
            parts.append("; ".join(execution.reading.problems))
        return False, unmet, "; ".join(parts)
    return True, [], "goal reached in the simulated world"


def tower_text(execution: Execution) -> str:
    """The towers standing at the end, top first, and the largest stacking offset."""
    lines = [" on ".join(reversed(t)) for t in towers(execution.reading.facts) if len(t) > 1]
    worst = max(execution.offsets.values(), default=0.0) * 1000
    return f"{'; '.join(lines) or 'no tower'} (largest xy offset {worst:.1f} mm)"


def run(
    scenario: Scenario,
    write: bool = True,
    quiet: bool = True,
    meshcat=None,
    started: float | None = None,
) -> RunResult:
    """The whole pipeline: check -> plan -> Diagram -> simulation -> verdict -> outputs.

    ``write=False`` writes nothing (for notebooks and studies). ``meshcat`` is a
    ``pydrake.geometry.Meshcat`` to watch; with ``scenario.visualization.meshcat`` and
    none given, one is started. ``started`` is when the process began (for the stage
    times in ``summary.json``).
    """
    t = time.perf_counter()
    stages: dict[str, float] = {}
    if started is not None:
        stages["import"] = t - started
    checked = check(scenario, write)
    problem = checked.problem
    view = blocksworld_view(problem)
    blocks = list(view.blocks)
    stacks = towers(view.init)
    initial = layout(stacks, scenario.world.slots)  # to warm up the renderer with
    if scenario.visualization.meshcat and meshcat is None:
        from pydrake.geometry import StartMeshcat

        meshcat = StartMeshcat()
    worker = None
    if checked.out is not None:
        from cake_drake.outputs.worker import OutputWorker

        worker = OutputWorker(
            blocks, initial, render=scenario.outputs.render, helpers=scenario.outputs.helpers
        )
    try:
        # A policy decides what to do; the plan still lays out the table as for the classical
        # run of the same task (and is recorded for comparison).
        plan, slots, initial = plan_and_layout(checked)
        stages["planning"] = time.perf_counter() - t
        if not quiet and checked.planner is not None:
            print(plan.note(), file=sys.stderr)
            if (
                problem.problem_path.endswith("problem_5.pddl")
                and plan.length != PROBLEM_5_OPTIMAL_LENGTH
            ):
                print(
                    f"note: problem_5's optimal plan has {PROBLEM_5_OPTIMAL_LENGTH} actions; "
                    f"{scenario.task.planner} is satisficing",
                    file=sys.stderr,
                )

        t = time.perf_counter()
        faults = resolve_faults(scenario.faults, blocks, plan.length, scenario.seed, slots)
        planner = checked.planner or PLANNER_REGISTRY[DEFAULT_PLANNER]
        cake = build_diagram(
            scenario,
            problem,
            initial,
            plan.actions,
            meshcat=meshcat,
            planner=planner,
            faults=faults,
            slots=slots,
        )
        stages["diagram_build"] = time.perf_counter() - t
        if worker is not None:  # drawn in the plot's helper while the world is simulated
            from cake_drake.outputs.report import cake_title, layers

            worker.submit_cake(layers(scenario, plan), cake_title(problem, cake))

        names = cake.reference.actions
        if cake.reference.policy is not None:  # a whole-task policy: its steps, its budget
            progress = ProgressBar(
                cake.reference.policy.max_steps, lambda k: "", enabled=not quiet, unit="step"
            )
        else:
            progress = ProgressBar(
                len(names), lambda k: f"({names[k]})" if k < len(names) else "", enabled=not quiet
            )
        if meshcat is not None:
            from cake_drake.outputs.replay import start_recording

            start_recording(meshcat)
        sim = scenario.simulation
        moves = [f for f in faults if isinstance(f, Move)]
        execution = execute(cake, sim.max_sim_s, sim.settle_s, progress=progress, moves=moves)
        for warning in execution.warnings:
            print(f"warning: collision: {warning}", file=sys.stderr)
        warn_saturation(execution.logs)
        stages["simulation"] = execution.wall_s
        if cake.ik is not None:
            stages["ik"] = sum(cake.ik.times_ms) / 1000
        success, unmet, message = verdict(problem, execution)
        result = RunResult(
            success, message, plan, execution, cake, problem, stages, [], unmet, faults
        )
        if checked.out is None:
            return result

        from cake_drake.outputs.files import OutputDir
        from cake_drake.outputs.report import write_outputs

        names = run_outputs(scenario, checked.generated)
        if meshcat is not None:
            names.add("replay.html")
        with OutputDir(checked.out, "run", names, run_inputs(scenario)) as staged:
            write_outputs(staged, result, worker, scenario.outputs.render, meshcat)
            if checked.generated is not None:
                staged.path("problem.pddl").write_text(checked.generated)
            result.written = staged.commit()
        return result
    finally:
        if worker is not None:
            worker.close()


__all__ = ["Checked", "RunResult", "check", "check_table_room", "get_plan", "run", "verdict"]


def warn_saturation(logs) -> None:
    """One stderr line when any joint's torque sat at the Panda's limit."""
    from cake_drake.dynamic.controllers import TORQUE_LIMITS

    sat = logs.saturation(TORQUE_LIMITS)
    hit = [j for j, s in enumerate(sat["saturated_s"]) if s > 0]
    if hit:
        joints = ", ".join(
            f"joint {j + 1} {sat['saturated_s'][j]:g} s (peak {sat['peak_nm'][j]:g} of "
            f"{TORQUE_LIMITS[j]:g} N m)"
            for j in hit
        )
        print(f"warning: torque saturated: {joints}", file=sys.stderr)
