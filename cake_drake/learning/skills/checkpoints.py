"""A learned skill checkpoint as the geometric layer's skill (:mod:`cake_drake.systems.skills`).

A skill is a ``cake_mlp`` trained with ``--inputs skill`` (``observation.state`` and
``observation.skill``, on a recording cut into per-action segments): its checkpoint says
so by its input features, so a scenario (``motion.skills``) and ``evaluate`` need no flag,
and a whole-task policy given as a skill (or the reverse) is refused before anything is
simulated (:func:`check_folder`, :func:`cake_drake.learning.policies.checkpoint.check_folder`).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from cake_drake import artifacts
from cake_drake.errors import InputError
from cake_drake.learning.data.dataset import require_lerobot
from cake_drake.learning.policies.expert import ClosedLoopExpert
from cake_drake.learning.policies.lerobot_checkpoint import (
    check_device,
    device_for,
    is_skill,
    model_folder,
    read_checkpoint,
)
from cake_drake.learning.policies.mlp.acting import load as load_mlp
from cake_drake.learning.skills import relative as relative_skill
from cake_drake.pipeline import check, get_plan, run
from cake_drake.policy.observations import SKILL_SIZE, relative_vector
from cake_drake.policy.spaces import step_budget
from cake_drake.scenario import Motion, Planned
from cake_drake.symbolic.roles import blocksworld_view

#: The action spaces a skill answers in, by the size of its action: seven joint targets
#: and the gripper's width; or a move of the hand and the gripper.
SKILL_ACTIONS = {8: "joint_position", 7: "ee_delta"}
#: ``motion.skill_action_space`` for a skill that never sees the arm.
RELATIVE = "relative"


def action_space_of(config: dict) -> str | None:
    """The action space a skill checkpoint's config answers in (None: no skill's)."""
    action = config.get("output_features", {}).get("action", {}).get("shape", [0])[0]
    return SKILL_ACTIONS.get(action)


def _relative(path: Path) -> bool:
    """Whether ``path`` holds a skill that never sees the arm (``skill.json``, or
    ``skill_rl.json``: one with an RL residual)."""
    kind = artifacts.kind_of(path)
    return kind is not None and kind.name in ("relative_skill", "skill_rl")


def _with_rl(path: Path) -> bool:
    kind = artifacts.kind_of(path)
    return kind is not None and kind.name == "skill_rl"


def check_folder(path: Path, device: str = "cpu", action_space: str = "") -> Path:
    """Refuse, in one line, a folder that is no skill: not a checkpoint, a whole-task
    policy, another skill layout or action space (``action_space``: the one the scenario
    asks for, ``relative`` for a skill that never sees the arm, empty for the folder's
    own), a device that is not here. The model's folder."""
    artifacts.require(path, *artifacts.SKILL_KINDS, role="motion.skills")  # the kind first
    if _relative(path):
        if action_space not in ("", RELATIVE):
            raise InputError(
                f"{path}: a skill that never sees the arm (skill.json: hand moves, the "
                f"gripper decided), run as motion.skill_action_space: {action_space}; leave "
                f"it empty or give {RELATIVE}"
            )
        if device not in ("cpu", "auto"):
            raise InputError(f"{path}: a skill that never sees the arm acts in NumPy on the "
                             f"CPU; motion.skill_device: cpu, not {device}")  # fmt: skip
        if _with_rl(path):
            from cake_drake.learning.skills import residual as skill_rl

            skill_rl.check_folder(path)
            return path
        return relative_skill.check_folder(path)
    if action_space == RELATIVE:
        artifacts.require(path, *artifacts.SKILL_KINDS, role="motion.skills")
        raise InputError(
            f"{path}: a skill that reads the arm's joints (a LeRobot checkpoint), run as "
            f"motion.skill_action_space: {RELATIVE}; give a folder with skill.json (python -m "
            "cake_drake.train --inputs relative), or leave the setting empty"
        )
    require_lerobot()
    folder = model_folder(path)
    config = read_checkpoint(folder)
    if not is_skill(config):
        raise InputError(
            f"{path}: a whole-task policy (it reads {', '.join(config.get('input_features', {}))}"
            "), not a learned skill; run it as reference: !Policy {checkpoint: ...}, or give "
            "motion.skills a checkpoint trained with --inputs skill"
        )
    if config.get("type") != "cake_mlp":
        raise InputError(f"{path}: a skill of type {config.get('type')!r}; skills are cake_mlp")
    size = config["input_features"]["observation.skill"]["shape"][0]
    if size != SKILL_SIZE:
        raise InputError(
            f"{path}: its observation.skill has {size} numbers; this cake_drake's has "
            f"{SKILL_SIZE} (pick-up, unstack, put-down, stack: train it again)"
        )
    action = config.get("output_features", {}).get("action", {}).get("shape", [0])[0]
    space = action_space_of(config)
    if space is None:
        raise InputError(
            f"{path}: the skill predicts {action} numbers an action; a skill answers in "
            "joint_position (8: 7 joints and the gripper) or ee_delta (7: a move of the "
            "hand and the gripper)"
        )
    if action_space and action_space != space:
        raise InputError(
            f"{path}: a skill trained on {space} actions ({action} numbers), run as "
            f"motion.skill_action_space: {action_space}; leave it empty or give {space}"
        )
    check_device(device)
    return folder


class CheckpointSkill:
    """The skill of a checkpoint folder: ``reset()`` at each new action, ``act`` a dict of
    ``observation.state`` and ``observation.skill`` -> an action in ``action_space`` (the
    checkpoint's: 8 joint-position numbers, or 7 of ee_delta)."""

    def __init__(self, path: str, device: str = "cpu", ensemble: float = 0.0) -> None:
        self.folder = check_folder(Path(path), device)
        self.action_space = action_space_of(read_checkpoint(self.folder))
        # A perceptron acts on the CPU unless a GPU is asked for by name (see
        # cake_drake.learning.policies.lerobot_checkpoint): then no torch is imported.
        self.device = "cpu" if device == "auto" else device_for(device)
        self.network = load_mlp(self.folder, self.device, ensemble)

    def reset(self) -> None:
        self.network.reset()

    def act(self, observation) -> np.ndarray:
        batch = {
            key: np.asarray(observation[key], np.float32)[None] for key in self.network.input_keys
        }
        return self.network.select_action(batch)[0].astype(np.float64)


def describe(path: str | Path) -> str:
    """What the skill at ``path`` reads and answers, for a run's ``layers``."""
    if _with_rl(Path(path)):
        from cake_drake.learning.skills import residual as skill_rl

        return skill_rl.describe(path)
    if _relative(Path(path)):
        return relative_skill.describe(path)
    config = read_checkpoint(model_folder(Path(path)))
    return (f"imitation, {config.get('type')}, reads the arm's joints, answers in "
            f"{action_space_of(config)}")  # fmt: skip


def make(path: str, device: str = "cpu", ensemble: float = 0.0):
    """The plug-in's factory (``motion.skills``: a skill's folder; ``ensemble``:
    ``motion.skill_ensemble``, for a checkpoint's action chunks): a skill that never sees
    the arm, or a LeRobot skill checkpoint."""
    if _with_rl(Path(path)):
        from cake_drake.learning.skills import residual as skill_rl

        return skill_rl.ResidualSkill(path)
    if _relative(Path(path)):
        return relative_skill.RelativeSkill(path)
    return CheckpointSkill(path, device, ensemble)


def episode(spec, seed: int) -> dict:
    """One evaluation episode of a skill checkpoint (``spec.options["path"]``): the episode
    ``spec.env()`` would run from ``seed`` (the same problem and placement), run instead
    with the planner's plan, the execution monitor (setting a loose goal stack down
    again: ``re_place``) and the skills as the geometric layer
    (an empty path: the classical geometric layer, for the row beside it); its row (as
    :func:`cake_drake.learning.rollout.rollout`'s, with the monitor's repeats and
    replans, the simulated time, and each stack's offset from the cube below)."""
    t0 = time.perf_counter()
    scenario = spec.env().episode_scenario(seed)
    scenario.reference = Planned(re_place=True)
    scenario.cameras = []
    motion = scenario.motion
    motion.skills = str(spec.options.get("path") or "")
    motion.skill_device = str(spec.options.get("device", "cpu"))
    if "ensemble" in spec.options:
        motion.skill_ensemble = float(spec.options["ensemble"])
    motion.skill_rate_hz = spec.rate_hz
    # The whole-task policy's budget for the same episode (steps of the same rate).
    n_actions = len(get_plan(check(scenario, write=False)).actions)
    budget = step_budget(spec.max_steps, n_actions, spec.rate_hz)
    scenario.simulation.max_sim_s = budget / spec.rate_hz
    result = run(scenario, write=False)
    monitoring = result.execution.monitoring
    skills = monitoring.get("skills") or {}
    events = monitoring.get("events", [])
    ok = result.success
    reason = "goal reached" if ok else result.message
    return {
        "seed": seed,
        "success": ok,
        "reason": reason,
        "steps": int(skills.get("steps", round(result.execution.sim_s * spec.rate_hz))),
        "wall_s": time.perf_counter() - t0,
        "task": "",
        "blocks": len(blocksworld_view(result.problem).blocks),
        "repeats": sum(e.get("kind") == "repeat" for e in events),
        "replans": int(monitoring.get("replans", 0)),
        "budget": budget,
        "sim_s": round(result.execution.sim_s, 2),
        # Each stack's cube, off the one below when the action ended (mm).
        "places_mm": [p["offset_mm"] for p in monitoring.get("places", [])],
    }


class SkillsUnderExpert:
    """DAgger's learner for skills: in the Gym env, the closed-loop expert chooses the
    ground action from the measured world (its plan, its repairs) and the skill
    executes it: the states learned skills drift into, for the teacher to label per
    action (:func:`cake_drake.learning.training.dagger.dagger` with ``--inputs skill`` or
    ``relative``). A skill that never sees the arm acts as the network alone: no shield
    step runs here. The skill's history is cleared when the action under way changes,
    as under the planner (:class:`cake_drake.systems.skills.LearnedSkills`); while no
    action is under way (waiting for the world to settle) the expert's own answer holds
    the hand."""

    def __init__(self, path: str, device: str = "cpu") -> None:
        # Acting as it does under the planner, its chunks ensembled as a run's are.
        self.skill = make(path, device, Motion.skill_ensemble)
        self.folder = Path(path)
        self.chooser = ClosedLoopExpert(max_repairs=None)
        self._ground: tuple | None = None

    def reset(self, task, seed: int) -> None:
        if task.action_space != self.skill.action_space:
            raise InputError(
                f"{self.folder}: a skill answering {self.skill.action_space}, rolled "
                f"out in an env of {task.action_space} actions; record the task of its space"
            )
        self.chooser.reset(task, seed)
        self._ground = None

    @property
    def reason(self) -> str | None:
        return self.chooser.reason

    def act(self, observation):
        answer = self.chooser.act(observation)
        if isinstance(answer, tuple):
            if answer[0] is None:  # (None, True): the expert is done
                return answer
            answer = answer[0]
        skill, ground = self.chooser.skill_observation()
        if ground[0] < 0:
            return answer
        if tuple(ground) != self._ground:
            self._ground = tuple(ground)
            self.skill.reset()
        state = np.asarray(observation["state"][:8], np.float32)
        return self.skill.act({
            "observation.state": state,
            "observation.skill": skill,
            "observation.relative": relative_vector(skill, float(state[7])),
        })  # fmt: skip


def under_expert(path: str, device: str = "cpu") -> SkillsUnderExpert:
    """The factory of DAgger's skill learner (``SKILL_LEARNER``)."""
    return SkillsUnderExpert(path, device)


#: The learner DAgger rolls out for a skill checkpoint (:func:`under_expert`, by the path
#: DAgger's records name).
SKILL_LEARNER = "cake_drake.learning.skills:under_expert"
