"""A run is data: one typed :class:`Scenario` tree, loaded from YAML and saved with every run.

Everything that shapes a run lives here - the task (domain, problem or plan file,
planner), the world (plant and contact settings, table slots), the motion (IK solver,
timing, waypoints, collision policy), the controller and its gains, the reference
(planned by the action source, or a recorded trajectory), the seed, the outputs and the
visualization. Files are read and written with Drake's typed YAML
(``pydrake.common.yaml``); a file may hold one scenario, or several by name::

    exercise_torque:
      controller: !ComputedTorque {kp: [100], kd: [20]}
    kd_5:
      controller: !ComputedTorque {kp: [100], kd: [5]}

``python -m cake_drake.run --scenario FILE [--name NAME]`` runs one, with flags as
overrides; every run writes the resolved ``scenario.yaml`` to its output folder, and
running that file again reproduces the run. Bad files are refused before anything is
built, with the file, the line and the valid keys or tags.

Paths in a scenario are ``package://cake_drake/...`` (the repository's ``models/``), an
absolute path, or a path relative to the scenario file's folder.
"""

import dataclasses
import math
import os
import sys
import typing
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from pydrake.common.yaml import yaml_dump_typed, yaml_load_typed

from cake_drake import __version__
from cake_drake.dynamic.controllers import (
    ComputedTorque,
    ControllerConfig,
    CustomController,
    JointPd,
    Pid,
)
from cake_drake.errors import InputError
from cake_drake.geometric.trajectory import Timing
from cake_drake.geometric.waypoints import WaypointParams
from cake_drake.paths import PACKAGE, portable_path, resolve_path
from cake_drake.perception import Perception
from cake_drake.symbolic import DEFAULT_PLANNER
from cake_drake.symbolic.learned import PREFIX as LEARNED_AT
from cake_drake.symbolic.sexpr import read_text
from cake_drake.world.cameras import Camera
from cake_drake.world.faults import FaultConfig, Knock, Move, RandomFault, Slip
from cake_drake.world.scene import WorldConfig


@dataclass
class Generate:
    """A seeded random Blocksworld problem (:func:`cake_drake.symbolic.random_problem`).

    Given in ``task.generate``, it takes the place of ``task.problem``: the same fields
    always write the same PDDL, which a run saves as ``problem.pddl``. ``style`` is the
    naming (``exercise``, ``ipc`` or ``typed``) and must fit ``task.domain``.
    """

    blocks: int = 5
    seed: int = 0
    style: str = "exercise"
    tall: bool = False  # few, tall towers (start and goal)
    partial: bool = False  # about half of the goal's on facts, no on-table fact
    max_height: int | None = None  # cap on the start towers' heights
    goal_max_height: int | None = None  # cap on the goal towers' heights


@dataclass
class Task:
    """What to do: a PDDL problem, solved by ``planner`` or by the plan in ``plan``."""

    domain: str = PACKAGE + "pddl/blocksworld.pddl"
    problem: str = PACKAGE + "pddl/problem_5.pddl"
    #: A generated problem instead of ``problem`` (for studies over many problems).
    generate: Generate | None = None
    #: Execute this plan file (plan.txt, .soln, sas_plan) instead of planning; validated first.
    plan: str = ""
    #: A planner of the registry (``python -m cake_drake.plan --help``), module:attribute,
    #: or ``learned@DIR``: a learned planner's checkpoint, DIR a scenario path like the
    #: files above (relative to the scenario file's folder).
    planner: str = DEFAULT_PLANNER
    time_limit: float | None = None  # s, for the planner


def _shield_steps() -> list[str]:
    """Every step of the learned skills' shield (imported when a scenario is made)."""
    from cake_drake.policy.shield import DEFAULT

    return list(DEFAULT)


@dataclass
class Motion:
    """The geometric layer: IK, timing, waypoints and what to do about collisions."""

    #: ``drake`` | ``dls`` or module:attribute (a factory ``(kinematics, seed) -> IkSolver``).
    ik: str = "drake"
    timing: Timing = field(default_factory=Timing)
    waypoints: WaypointParams = field(default_factory=WaypointParams)
    collision_check: bool = True  # report planned moves that sweep through cubes
    avoid_collisions: bool = False  # re-plan such moves higher or with the hand turned
    #: ``straight`` (the exercise's joint-space lines, blocked or not), ``rrt-connect``
    #: (grasps and places chosen free, blocked moves planned with OMPL) or
    #: module:attribute (a factory ``() -> planner``, see cake_drake.geometric.planners).
    planner: str = "straight"
    #: The geometric layer learned: a skill checkpoint (a folder from ``python -m
    #: cake_drake.train --inputs skill``) executes each ground action in place of the
    #: waypoints and IK above (cake_drake.systems.skills); empty: the classical layer.
    skills: str = ""
    skill_rate_hz: float = 10.0  # how often the skill is asked (its recording's rate)
    #: Control periods one action may take before it is handed back to the action source
    #: (0: 150, 15 s at 10 Hz).
    skill_max_steps: int = 0
    skill_device: str = "cpu"  # where the skill runs: cpu | cuda | auto
    #: What the skill answers in (joint_position | ee_delta), or ``relative``: a skill that
    #: never sees the arm (skill.json); empty: what its folder holds. A skill of another
    #: kind or space is refused before anything runs.
    skill_action_space: str = ""
    #: The skill's joint targets reach the controller through a critically damped filter
    #: that settles on each in about this many seconds, continuous in position and
    #: velocity; 0: as steps held until the next answer (how the skills were first run).
    skill_smooth_s: float = 0.0
    #: ACT's temporal ensembling of the skill's action chunks: a chunk predicted every
    #: control period, each action the mean of every chunk's prediction for it, the older
    #: weighted exp(-skill_ensemble * i) (i = 0 the oldest); 0: a chunk's first actions
    #: executed open loop, then a new chunk (how the skills were trained).
    skill_ensemble: float = 0.01
    #: The shield's steps around the skill's network, by name, in the order they run
    #: within their phase (cake_drake.policy.shield.STEPS); ``[]``: the network alone.
    skill_rules: list[str] = field(default_factory=lambda: _shield_steps())


@dataclass
class Planned:
    """The reference comes from an action source, through the waypoint/IK layer."""

    #: ``monitor`` (the plan, each action checked against the measured world, replanned
    #: when it disagrees), ``plan`` (open loop) or module:attribute of a factory
    #: ``(SourceContext) -> System`` (see :func:`cake_drake.systems.make_action_source`).
    action_source: str = "monitor"
    max_replans: int = 5  # the monitor's budget of replans in one run
    #: The monitor sets a goal's stacked cube down again when it stands farther off the
    #: one below than the verdict allows (a replan: the cubes above it to the table, then
    #: it picked and stacked once more). Off by default: a classical place is precise to
    #: about a millimetre; learned skills (motion.skills) are not, and the shipped
    #: learned_tower5 turns it on.
    re_place: bool = False


@dataclass
class Recorded:
    """Replay a recorded ``trajectory.npz`` (exercise 4.x.3) instead of planning motion."""

    path: str = ""
    differentiate: str = "spline"  # how q-dot and q-double-dot are recovered: spline | central


#: Wall-clock budget (s) of one answer of a policy, unless ``reference.act_budget_s`` says.
ACT_BUDGET_S = 30.0


@dataclass
class Policy:
    """A policy drives the arm (the learned layer's slot): ``factory`` (``module:attribute``)
    called as ``factory(**options)`` returns an object with ``reset(task, seed)`` and
    ``act(observation) -> action`` (or ``(action, done)``), asked ``rate_hz`` times a
    simulated second; its action, in ``action_space`` (:mod:`cake_drake.policy.spaces`),
    is held until the next step. The run ends when the policy says done, or after
    ``max_steps`` steps (0: scaled to the task, 20 s plus 8 s per action of the classical
    plan); the verdict is measured from the poses, as for any run, and says when the
    budget ran out."""

    factory: str = ""
    action_space: str = "joint_position"  # joint_position | ee_delta | joint_chunk
    rate_hz: float = 10.0
    max_steps: int = 0  # 0: scaled to the task's plan
    options: dict[str, float] = field(default_factory=dict)
    #: A trained policy instead of a factory: a folder written by ``python -m
    #: cake_drake.train`` (or any LeRobot checkpoint folder), run through its processors.
    checkpoint: str = ""
    device: str = "auto"  # where a checkpoint runs: auto | cpu | cuda
    #: Wall-clock budget (s) of one answer of the policy: one that takes longer ends the
    #: run or the episode (exit 3). A Diffusion Policy's 100 denoising passes on a busy
    #: CPU want more than the default.
    act_budget_s: float = ACT_BUDGET_S
    #: Each joint target reaches the controller through a critically damped filter that
    #: settles on it in about this many seconds (continuous in position and velocity);
    #: 0: held as a step until the next (see cake_drake.systems.waypoint_ik).
    smooth_s: float = 0.0


@dataclass
class ImageRecipe:
    """What a task's recipe changes when the policy sees (``train --inputs images``, or a
    recipe whose ``inputs`` is ``images``): a camera's encoder costs more a sample than
    the numbers, so fewer samples a step."""

    steps: int = 8000
    batch_size: int = 64
    #: Random shift of each training image, in pixels (0: none).
    crop_shift: int = 4
    #: The cameras it reads, by name (none named: every camera the recording has).
    cameras: list[str] = field(default_factory=list)


@dataclass
class PolicyRecipe:
    """What a task's recipe changes when another of its policies trains (``train --policy
    act`` on a task whose recipe trains ``mlp``): a transformer or a U-Net wants another
    learning rate, batch and length than the MLP. Unset fields keep the recipe's."""

    steps: int | None = None
    batch_size: int | None = None
    lr: float | None = None
    chunk_size: int | None = None
    n_action_steps: int | None = None
    inference_steps: int | None = None


@dataclass
class Reward:
    """What a step of reinforcement learning is worth: a weight per term, each term a
    number from 0 to 1 read from the measured world at every step
    (:mod:`cake_drake.learning.envs.rewards` defines them). Unset, ``goal`` weighs 1 and the
    others 0: the Gym env's own reward."""

    #: The fraction of the goal's facts measured true (the Gym env's own reward).
    goal: float = 1.0
    #: 1 at the step the goal is reached (every fact, every stack within 5 mm).
    success: float = 0.0
    #: The hand's nearness to the first cube the goal still wants moved (1 at its centre,
    #: 1 - tanh(d / 20 cm) away from it).
    reach: float = 0.0
    #: How far the cubes the goal still wants moved are raised (1 from one cube's height).
    lift: float = 0.0
    #: Each goal-stacked cube's horizontal alignment over the one it goes on, while above
    #: it (1 centred, 0 from 10 mm): precision, the last millimetres.
    place: float = 0.0
    #: 1 every step: a negative weight is the cost of time, so that ending an episode by
    #: success is worth more than lingering near it.
    step: float = 0.0
    #: 1 at the step a cube leaves the table (the episode ends there): a negative weight
    #: keeps the cost of time from paying for throwing a cube away.
    lost: float = 0.0


@dataclass
class RlRecipe:
    """How a task is learned from a reward (``python -m cake_drake.train --rl``): a
    Stable-Baselines3 algorithm on ``CakeDrake/Stack-v0`` with the task's episodes, from
    scratch, or as a bounded residual on a frozen policy (``base``)."""

    algorithm: str = "ppo"  # ppo | sac
    #: Environment steps in all (every environment's together).
    steps: int = 100_000
    #: A wall-clock budget: the training stops at the first step past it, even short of
    #: ``steps`` (0: none). Two recipes compared at equal time set the same.
    minutes: float = 0.0
    #: Environments stepped side by side (Gymnasium's make_vec; 1: in this process).
    envs: int = 2
    #: A frozen policy's checkpoint the learner corrects (a residual); empty: from scratch.
    base: str = ""
    #: The residual's bound: at most this much added to each joint target (rad).
    residual_scale: float = 0.05
    #: ... and to the gripper's command (0: the base's own).
    residual_gripper: float = 0.0
    #: PPO: steps each environment takes between updates, the updates' batch and passes.
    rollout: int = 512
    batch_size: int = 128
    epochs: int = 5
    lr: float = 3.0e-4
    gamma: float = 0.99
    #: The policy's (and value's) hidden layers.
    hidden_dims: list[int] = field(default_factory=lambda: [256, 256])
    #: The initial exploration noise (PPO's log-std): small for a residual.
    log_std: float = -1.0
    #: An episode's step budget (0: the task's ``reference.max_steps``).
    max_steps: int = 0
    #: A skill residual's held-out checks: every this many steps (0: none), on this many
    #: places, without exploration; the best check's model is the one kept.
    eval_every: int = 0
    eval_episodes: int = 20
    #: A skill residual's start pool (``python -m cake_drake.record SPEC --starts FILE``):
    #: its episodes start from the pool's states, nothing replayed; empty: each start
    #: replays the base's actions before its place. Held-out checks always replay.
    starts: str = ""
    reward: Reward = field(default_factory=Reward)


@dataclass
class Training:
    """A learning task's recipe for ``python -m cake_drake.train``: LeRobot's policy, what it
    reads, how long it trains and how big its network is (data, not code)."""

    policy: str = "act"  # act | diffusion | mlp
    inputs: str = "state"  # state | images | both | skill | relative
    steps: int = 20000
    batch_size: int = 64
    lr: float = 1e-4
    #: The transformer's width and depth (ACT), or the U-Net's widths (Diffusion Policy).
    dim_model: int = 128
    n_heads: int = 4
    dim_feedforward: int = 512
    n_encoder_layers: int = 2
    down_dims: list[int] = field(default_factory=lambda: [64, 128, 256])
    #: The MLP's hidden layers (mlp).
    hidden_dims: list[int] = field(default_factory=lambda: [512, 512, 512])
    #: Actions predicted at once, and how many of them are executed before asking again.
    chunk_size: int = 20
    n_action_steps: int = 10
    #: Observations the MLP reads at once: the current one and those before it (mlp).
    n_obs_steps: int = 1
    #: Diffusion Policy's denoising passes an answer: 0, all of its 100 training steps
    #: (DDPM); fewer, evenly spaced with DDIM (10 answer ten times as fast).
    inference_steps: int = 0
    #: The recipe's changes when the policy reads the cameras instead of the poses.
    images: ImageRecipe = field(default_factory=ImageRecipe)
    #: The recipe's changes when ACT or Diffusion Policy trains instead (train --policy).
    act: PolicyRecipe = field(default_factory=PolicyRecipe)
    diffusion: PolicyRecipe = field(default_factory=PolicyRecipe)
    #: How the task is learned from a reward instead (train --rl).
    rl: RlRecipe = field(default_factory=RlRecipe)


ReferenceConfig = Planned | Recorded | Policy


@dataclass
class Simulation:
    """How long the world runs."""

    settle_s: float = 0.3  # after the last action, before the poses are read
    max_sim_s: float = 300.0  # simulated-time budget
    #: Wall-clock budget (s) of each 0.05 s of simulated time while plug-ins run inside
    #: the simulation (an action source, a controller): one that hangs ends the run (exit 3).
    step_budget_s: float = 60.0


#: ``outputs.helpers``: fork the output helpers when a core is free, always, or never.
HELPER_CHOICES = ("auto", "always", "never")


@dataclass
class Outputs:
    folder: str = "outputs"
    render: bool = True  # final_state.png
    #: Draw the picture and the plot in helper processes that overlap the simulation:
    #: ``auto`` when a core is free (a busy machine gains nothing from them), ``always``
    #: or ``never``. The files are the same either way.
    helpers: str = "auto"
    #: Write ``logs.npz``: everything the loggers recorded (``t``, ``q``, ``v``, ``q_d``,
    #: ``v_d``, ``a_d``, ``tau_applied``, ``fingers``, ...), the data a learned residual
    #: is fitted to (``python -m cake_drake.train --residual``).
    logs: bool = False


@dataclass
class Visualization:
    meshcat: bool = False  # show the run live in Meshcat and write replay.html
    #: Simulated seconds per wall second to hold the simulation to (0: as fast as it goes;
    #: ``--meshcat`` from a terminal sets 1, real time, to watch).
    realtime_rate: float = 0.0


@dataclass
class Scenario:
    """Everything that shapes one run."""

    task: Task = field(default_factory=Task)
    world: WorldConfig = field(default_factory=WorldConfig)
    motion: Motion = field(default_factory=Motion)
    controller: ControllerConfig = field(default_factory=ComputedTorque)
    reference: ReferenceConfig = field(default_factory=Planned)
    simulation: Simulation = field(default_factory=Simulation)
    outputs: Outputs = field(default_factory=Outputs)
    visualization: Visualization = field(default_factory=Visualization)
    #: Disturbances of the world (cake_drake.world.faults): !Slip, !Knock, !Move, !RandomFault.
    faults: list[FaultConfig] = field(default_factory=list)
    #: Cameras in the world (cake_drake.world.cameras); none by default (no renderer then).
    cameras: list[Camera] = field(default_factory=list)
    #: Where the cake's knowledge of the cubes comes from (docs/perception.md).
    perception: Perception = field(default_factory=Perception)
    #: How a policy learns this task (python -m cake_drake.train): the learning tasks' recipe.
    training: Training = field(default_factory=Training)
    seed: int = 0  # IK restarts draw from it; the same seed gives the same run


# --- paths -------------------------------------------------------------------------------


#: The learned layers' adapters, through the plug-in door (nothing outside learning/
#: imports them): a whole-task policy's checkpoint, a learned skill's; and their checks.
CHECKPOINT_POLICY = "cake_drake.learning.checkpoint:make"
CHECKPOINT_CHECK = "cake_drake.learning.checkpoint:check_folder"
CHECKPOINT_DESCRIBE = "cake_drake.learning.checkpoint:describe"
SKILL_POLICY = "cake_drake.learning.skills:make"
SKILL_CHECK = "cake_drake.learning.skills:check_folder"
SKILL_DESCRIBE = "cake_drake.learning.skills:describe"


def _scenario_paths(scenario: Scenario):
    """(section, field, prefix) for every path field, for resolving and saving: the field's
    value is ``prefix`` then the path (``learned@DIR``: a learned planner's folder)."""
    yield scenario.task, "domain", ""
    yield scenario.task, "problem", ""
    if scenario.task.plan:
        yield scenario.task, "plan", ""
    if scenario.task.planner.startswith(LEARNED_AT) and scenario.task.planner != LEARNED_AT:
        yield scenario.task, "planner", LEARNED_AT
    if isinstance(scenario.reference, Recorded) and scenario.reference.path:
        yield scenario.reference, "path", ""
    if isinstance(scenario.reference, Policy) and scenario.reference.checkpoint:
        yield scenario.reference, "checkpoint", ""
    if getattr(scenario.controller, "residual", ""):
        yield scenario.controller, "residual", ""
    if scenario.motion.skills:
        yield scenario.motion, "skills", ""


def resolved(scenario: Scenario, base: Path | None) -> Scenario:
    """A copy with every path absolute (or a package URL), relative ones taken from ``base``."""
    out = _copy(scenario)
    for section, name, prefix in _scenario_paths(out):
        path = getattr(section, name)[len(prefix) :]
        if not path:  # no file (a generated problem has no problem file)
            continue
        try:
            setattr(section, name, prefix + portable_path(resolve_path(path, base)))
        except InputError as e:  # the field it was given in, before the path's fault
            where = next(f.name for f in dataclasses.fields(out) if getattr(out, f.name) is section)
            raise InputError(f"{where}.{name}: {e}") from None
    return out


def _copy(scenario: Scenario) -> Scenario:
    return yaml_load_typed(schema=Scenario, data=yaml_dump_typed(scenario))


# --- loading -----------------------------------------------------------------------------


def _fields(schema) -> dict[str, object]:
    hints = typing.get_type_hints(schema)
    return {f.name: hints[f.name] for f in dataclasses.fields(schema)}


def _union_members(tp) -> tuple:
    if typing.get_origin(tp) in (typing.Union, getattr(__import__("types"), "UnionType", None)):
        return typing.get_args(tp)
    return ()


def _where(source: str, node: yaml.Node) -> str:
    if source.startswith(SET_FLAG):  # a setting is one line of the command's
        return source
    return f"{source}:{node.start_mark.line + 1}"


def _check_node(node: yaml.Node, tp, source: str, path: str) -> None:
    """Walk the YAML node against the schema type, so errors name the line."""
    members = _union_members(tp)
    if members:
        if isinstance(node, yaml.ScalarNode) and node.value in ("null", "~", ""):
            if type(None) in members:
                return
        classes = [m for m in members if dataclasses.is_dataclass(m)]
        if classes:
            tag = node.tag if node.tag.startswith("!") and not node.tag.startswith("!!") else None
            if tag is None:
                chosen = classes[0]
            else:
                by_tag = {f"!{c.__name__}": c for c in classes}
                if tag not in by_tag:
                    raise InputError(
                        f"{_where(source, node)}: {path} has unknown tag {tag}; "
                        f"valid tags: {', '.join(by_tag)}"
                    )
                chosen = by_tag[tag]
            _check_node(node, chosen, source, path)
            return
        others = [m for m in members if m is not type(None)]
        _check_node(node, others[0], source, path)
        return
    if dataclasses.is_dataclass(tp):
        if not isinstance(node, yaml.MappingNode):
            raise InputError(
                f"{_where(source, node)}: {path or 'the scenario'} must be a mapping of "
                f"{', '.join(_fields(tp))}"
            )
        fields = _fields(tp)
        seen = set()
        for key_node, value_node in node.value:
            key = key_node.value
            if key == "<<":
                continue
            if key not in fields:
                raise InputError(
                    f"{_where(source, key_node)}: unknown key {key!r} in "
                    f"{path or 'the scenario'}; valid keys: {', '.join(fields)}"
                )
            if key in seen:
                raise InputError(f"{_where(source, key_node)}: key {key!r} given twice")
            seen.add(key)
            _check_node(value_node, fields[key], source, f"{path}.{key}" if path else key)
        return
    origin = typing.get_origin(tp)
    if origin is list:
        if not isinstance(node, yaml.SequenceNode):
            raise InputError(f"{_where(source, node)}: {path} must be a list, e.g. [1.0]")
        (item,) = typing.get_args(tp)
        for i, child in enumerate(node.value):
            _check_node(child, item, source, f"{path}[{i}]")
        return
    if origin is dict:
        if not isinstance(node, yaml.MappingNode):
            raise InputError(f"{_where(source, node)}: {path} must be a mapping")
        _, value_type = typing.get_args(tp)
        for key_node, value_node in node.value:
            _check_node(value_node, value_type, source, f"{path}.{key_node.value}")
        return
    if not isinstance(node, yaml.ScalarNode):
        raise InputError(f"{_where(source, node)}: {path} must be a single {tp.__name__}")
    value = node.value
    ok = True
    if tp is bool:
        ok = value.lower() in ("true", "false", "yes", "no", "on", "off")
    elif tp is int:
        ok = _parses(int, value)
    elif tp is float:
        ok = _parses(float, value) and math.isfinite(float(value))
    if tp is int and ok and not -(2**63) <= int(value) < 2**63:
        raise InputError(
            f"{_where(source, node)}: {path} = {_short(value)} is out of range (a 64-bit integer)"
        )
    if not ok:
        raise InputError(
            f"{_where(source, node)}: {path} = {_short(value)} is not a "
            f"{'finite number' if tp is float else tp.__name__}"
        )


def _short(value: str) -> str:
    return repr(value) if len(value) <= 24 else repr(value[:20] + "...")


def _parses(kind, value: str) -> bool:
    try:
        kind(value)
    except ValueError:
        return False
    return True


#: The most YAML nodes a file may stand for once its aliases and merge keys are expanded
#: (a scenario has a few hundred; a sweep a few thousand).
MAX_YAML_NODES = 100_000


def _top_level(text: str, source: str) -> yaml.Node | None:
    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        line = f":{mark.line + 1}" if mark else ""
        problem = getattr(e, "problem", None) or str(e).splitlines()[0]
        raise InputError(f"{source}{line}: not valid YAML ({problem})") from None
    except RecursionError:
        raise InputError(f"{source}: nested too deeply to be a scenario") from None
    if root is not None and _expanded_size(root) > MAX_YAML_NODES:
        raise InputError(
            f"{source}: its aliases and merge keys expand to more than {MAX_YAML_NODES:,} "
            "values; write the values out, or use fewer nested aliases"
        )
    return root


def _expanded_size(root: yaml.Node) -> int:
    """How many nodes ``root`` stands for with every alias expanded, counted without
    expanding (each shared node once, by identity); stops counting past the bound."""
    sizes: dict[int, int] = {}
    order: list[yaml.Node] = []
    stack, seen = [root], set()
    while stack:  # children before parents
        node = stack.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        order.append(node)
        if isinstance(node, yaml.SequenceNode):
            stack.extend(node.value)
        elif isinstance(node, yaml.MappingNode):
            stack.extend(n for pair in node.value for n in pair)
    for node in reversed(order):
        if isinstance(node, yaml.SequenceNode):
            children = node.value
        elif isinstance(node, yaml.MappingNode):
            children = [n for pair in node.value for n in pair]
        else:
            children = []
        sizes[id(node)] = min(1 + sum(sizes.get(id(c), 1) for c in children), 1 << 62)
    return sizes[id(root)]


def parse_scenario(text: str, source: str = "<string>", name: str | None = None) -> Scenario:
    """A :class:`Scenario` from YAML text: one scenario, or ``name`` of several."""
    root = _top_level(text, source)
    if root is None:
        if name:
            raise InputError(f"{source}: empty file, no scenario {name!r}")
        return Scenario()
    if not isinstance(root, yaml.MappingNode):
        raise InputError(f"{_where(source, root)}: a scenario file is a mapping")
    keys = [k.value for k, _ in root.value]
    fields = _fields(Scenario)
    # Several named scenarios: no key is a Scenario field and every value is a mapping.
    named = name is not None or (
        not set(keys) & set(fields) and all(isinstance(v, yaml.MappingNode) for _, v in root.value)
    )
    if named:
        if name is None:
            raise InputError(
                f"{source} holds the scenarios {', '.join(keys)}: choose one with --name"
            )
        seen: set[str] = set()
        for key_node, _ in root.value:
            if key_node.value in seen:
                raise InputError(
                    f"{_where(source, key_node)}: scenario {key_node.value!r} given twice; "
                    "each scenario of a file needs a name of its own"
                )
            seen.add(key_node.value)
        entries = dict((k.value, v) for k, v in root.value)
        if name not in entries:
            raise InputError(
                f"{source}: no scenario named {name!r}; it holds {', '.join(keys) or 'none'}"
            )
        node = entries[name]
        _check_node(node, Scenario, source, "")
        try:
            return yaml_load_typed(schema=Scenario, data=text, child_name=name)
        except Exception as e:  # noqa: BLE001 - the typed loader's message, as one line
            raise InputError(f"{source}: scenario {name!r}: {_first_line(e)}") from None
    _check_node(root, Scenario, source, "")
    try:
        return yaml_load_typed(schema=Scenario, data=text)
    except Exception as e:  # noqa: BLE001
        raise InputError(f"{source}: {_first_line(e)}") from None


def _first_line(e: Exception) -> str:
    return (str(e).strip().splitlines() or [type(e).__name__])[0]


def load_scenario(
    path: str | Path, name: str | None = None, settings: Sequence[str] = ()
) -> Scenario:
    """Read a scenario file; relative paths inside it are taken from the file's folder.
    ``settings`` (``--set``'s) are written over it (:func:`with_settings`)."""
    path = Path(path)
    text = read_text(path, "scenario file (*.yaml)", allow_empty=True)
    scenario = parse_scenario(text, str(path), name)
    try:
        scenario = resolved(scenario, path.resolve().parent)
    except InputError as e:
        raise InputError(f"{path}: {e}") from None
    return with_settings(scenario, settings)


#: The flag that sets any scenario field from the command line.
SET_FLAG = "--set"


def with_settings(scenario: Scenario, settings: Sequence[str]) -> Scenario:
    """``scenario`` with each ``section.field=VALUE`` written over it, in order: VALUE is
    read as YAML (``depth``, ``0.5``, ``[100, 100]``, ``!Pid {kp: [50]}``) and checked as a
    scenario file's field is (an unknown field or a wrong type is one line naming it); a
    relative path in it is taken from the working folder."""
    for given in settings:
        key, eq, value = given.partition("=")
        parts = key.split(".")
        if not eq or not all(part.isidentifier() for part in parts) or "\n" in value:
            raise InputError(
                f"{SET_FLAG} {given!r:.80}: give section.field=VALUE, the value as YAML "
                "(e.g. --set perception.estimator=depth); sections: "
                f"{', '.join(_fields(Scenario))}"
            )
        text = "".join(f"{'  ' * i}{part}:\n" for i, part in enumerate(parts[:-1]))
        text += f"{'  ' * (len(parts) - 1)}{parts[-1]}: {value}\n"
        source = f"{SET_FLAG} {key}"
        root = _top_level(text, source)
        _check_node(root, Scenario, source, "")
        try:
            scenario = yaml_load_typed(schema=Scenario, data=text, defaults=scenario)
        except Exception as e:  # noqa: BLE001 - the typed loader's message, as one line
            raise InputError(f"{source}: {_first_line(e)}") from None
        try:
            scenario = resolved(scenario, Path.cwd())
        except InputError as e:  # it names the field set
            raise InputError(f"{SET_FLAG} {e}") from None
    return scenario


def scenario_names(path: str | Path) -> list[str]:
    """The names of the scenarios a file holds (empty for a single-scenario file)."""
    root = _top_level(read_text(path, "scenario file (*.yaml)", allow_empty=True), str(path))
    if not isinstance(root, yaml.MappingNode):
        return []
    keys = [k.value for k, _ in root.value]
    if set(keys) & set(_fields(Scenario)):
        return []
    return keys if all(isinstance(v, yaml.MappingNode) for _, v in root.value) else []


# --- saving ------------------------------------------------------------------------------


def package_versions() -> dict[str, str]:
    """Versions of the packages a run's result depends on.

    Read from the names of their ``*.dist-info`` folders, as pip installs them: importing
    ``importlib.metadata`` alone costs a run more than writing all its other files.
    """
    names = ("drake", "numpy", "pyperplan", "matplotlib")
    found: dict[str, str] = {}
    for entry in sys.path:
        try:
            folders = os.listdir(entry or ".")
        except OSError:
            continue
        for folder in folders:
            name, _, rest = folder.partition("-")
            if rest.endswith(".dist-info") and name.lower() in names and name.lower() not in found:
                found[name.lower()] = rest[: -len(".dist-info")]
    missing = [n for n in names if n not in found]
    if missing:  # installed some other way: ask the slow, general lookup
        from importlib.metadata import PackageNotFoundError, version

        for name in missing:
            try:
                found[name] = version(name)
            except PackageNotFoundError:
                found[name] = "not installed"
    return {"cake_drake": __version__, **{n: found[n] for n in names}}


def dump_scenario(scenario: Scenario) -> str:
    """YAML text of ``scenario`` (every field, defaults included) with a versions header."""
    versions = ", ".join(f"{k} {v}" for k, v in package_versions().items())
    header = (
        "# The resolved scenario of a cake_drake run. Re-run it with\n"
        "#   python -m cake_drake.run --scenario scenario.yaml --out OTHER_FOLDER\n"
        f"# Recorded with: {versions}\n"
    )
    if scenario.perception.estimator != "truth" and not scenario.perception.cameras:
        scenario = _copy(scenario)  # the cameras it used, written out (not "the defaults")
        scenario.perception.cameras = scenario.perception.views()
    return header + yaml_dump_typed(scenario)


def controller_for_mode(mode: str) -> ControllerConfig:
    """The shipped controller a ``--mode`` names."""
    from cake_drake.dynamic.controllers import MODES

    try:
        return MODES[mode]()
    except KeyError:
        raise InputError(f"unknown mode {mode!r}; choose one of: {', '.join(MODES)}") from None


__all__ = [
    "ComputedTorque",
    "Knock",
    "Move",
    "RandomFault",
    "Slip",
    "CustomController",
    "Generate",
    "JointPd",
    "Pid",
    "Motion",
    "Outputs",
    "Planned",
    "Policy",
    "Recorded",
    "Reward",
    "RlRecipe",
    "Scenario",
    "Simulation",
    "Task",
    "Training",
    "Visualization",
    "dump_scenario",
    "load_scenario",
    "parse_scenario",
    "resolve_path",
]
