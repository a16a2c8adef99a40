"""The learned things, one table: what each kind is, how a folder says which it is, and the
one checked loader and describer of each.

A learned part of the cake is a folder, and its kind is decided here, once, from the files
it already has; nothing is re-saved to say so:

==========  ==============================  =========================================
kind        the folder holds                what it replaces
==========  ==============================  =========================================
rl          ``rl.json``, ``model.zip``      a whole-task policy learned from a reward
                                            (alone, or a residual on a frozen base)
planner     ``planner.json``,               the symbolic layer's planner
            ``weights.npz``
residual    ``residual.json``               a residual torque beside computed torque
skill       a LeRobot checkpoint whose      the geometric layer (a skill per ground
            inputs name ``observation.      action, under the planner), reading the
            skill``                         arm's joints
relative_   ``skill.json``,                 the geometric layer, never seeing the arm
skill       ``weights.npz``                 (hand moves with IK below, the gripper as
                                            a decision)
skill_rl    ``skill_rl.json``,              the same, a relative skill with an RL
            ``model.zip``                   residual on its hand moves
perception  ``perception.json``,            the perception layer's fit (a cube's pose
            ``weights.npz``                 from its depth points)
policy      any other LeRobot checkpoint    the symbolic and geometric layers (a
            (``config.json``,               whole-task policy)
            ``model.safetensors``)
==========  ==============================  =========================================

:func:`detect` names the kind; :func:`require` refuses, in one line, a folder of another
kind than the caller runs (a skill given as a whole-task policy, a planner given to
``evaluate``); :func:`check`, :func:`load` and :func:`describe` go to that kind's own
functions, named in :data:`KINDS` as plug-in strings (``module:attribute``): this is the
one place that names the modules of the learned half, and it imports none of them until
a kind is used (they need torch, LeRobot or Stable-Baselines3). A new kind registers here.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from cake_drake.errors import InputError
from cake_drake.formats import read_json_mapping
from cake_drake.plugins import load_attribute


@dataclass(frozen=True)
class Kind:
    """One kind of learned thing: its name, what it is (for messages), the layer it
    fills, and its functions as plug-in strings."""

    name: str
    what: str
    layer: str
    #: ``check(path, **needs)``: refuse, in one line, a folder that cannot run as asked.
    check: str
    #: ``load(path, **options)``: the loaded thing (a policy, a skill, a planner, a model).
    load: str
    #: ``describe(path) -> str``: one phrase for a run's ``layers`` and for messages.
    describe: str


_POLICIES = "cake_drake.learning.policies"
_SKILLS = "cake_drake.learning.skills"
KINDS: dict[str, Kind] = {
    kind.name: kind
    for kind in (
        Kind("rl", "an RL training's folder (rl.json)", "symbolic + geometric",
             f"{_POLICIES}.rl:check_folder", f"{_POLICIES}.rl:RlPolicy",
             f"{_POLICIES}.rl:describe"),
        Kind("planner", "a learned planner (planner.json)", "symbolic",
             "cake_drake.symbolic.learned:load_planner", "cake_drake.symbolic.learned:load_planner",
             "cake_drake.symbolic.learned:describe_folder"),
        Kind("residual", "a learned residual (residual.json)", "dynamic",
             "cake_drake.dynamic.residual:load_model", "cake_drake.dynamic.residual:load_model",
             "cake_drake.learning.training.residual:describe"),
        Kind("skill", "a learned skill (a checkpoint reading observation.skill)", "geometric",
             f"{_SKILLS}.checkpoints:check_folder", f"{_SKILLS}.checkpoints:make",
             f"{_SKILLS}.checkpoints:describe"),
        Kind("relative_skill", "a skill that never sees the arm (skill.json)", "geometric",
             f"{_SKILLS}.relative:check_folder", f"{_SKILLS}.relative:make",
             f"{_SKILLS}.relative:describe"),
        Kind("skill_rl", "a skill with an RL residual (skill_rl.json)", "geometric",
             f"{_SKILLS}.residual:check_folder", f"{_SKILLS}.residual:make",
             f"{_SKILLS}.residual:describe"),
        Kind("perception", "a learned cube estimator (perception.json)", "perception",
             "cake_drake.perception.learned:check_folder", "cake_drake.perception.learned:load",
             "cake_drake.perception.learned:describe"),
        Kind("policy", "a whole-task policy (a LeRobot checkpoint)", "symbolic + geometric",
             f"{_POLICIES}.lerobot_checkpoint:check_folder",
             f"{_POLICIES}.lerobot_checkpoint:CheckpointPolicy",
             f"{_POLICIES}.lerobot_checkpoint:describe"),
    )
}  # fmt: skip

#: The file that says a folder is of a kind, for the kinds that have one of their own.
MARKERS = {"rl": "rl.json", "planner": "planner.json", "residual": "residual.json",
           "relative_skill": "skill.json", "skill_rl": "skill_rl.json",
           "perception": "perception.json"}  # fmt: skip
#: The kinds that are the geometric layer (``motion.skills``, ``evaluate``'s skills).
SKILL_KINDS = ("skill", "relative_skill", "skill_rl")


def lerobot_folder(path: Path) -> Path | None:
    """The folder with a LeRobot checkpoint's ``config.json`` and weights: ``path``
    itself, or a training folder's last checkpoint; None where there is none."""
    for candidate in (
        path,
        path / "pretrained_model",
        path / "checkpoints" / "last" / "pretrained_model",
    ):
        if (candidate / "config.json").is_file() and (candidate / "model.safetensors").is_file():
            return candidate
    return None


def detect(path: str | Path) -> Kind:
    """The kind of the learned thing at ``path``, from the files it has (see the module);
    one line naming the folder and what would be valid where it is none of them."""
    path = Path(path).expanduser()
    if not path.exists():
        raise InputError(f"{path}: no such folder (a learned part: {_kinds_said()})")
    if not path.is_dir():
        raise InputError(f"{path}: a learned part is a folder ({_kinds_said()})")
    for name, marker in MARKERS.items():
        if (path / marker).is_file():
            return KINDS[name]
    folder = lerobot_folder(path)
    if folder is None:
        raise InputError(
            f"{path}: not a LeRobot checkpoint (no config.json and model.safetensors here, "
            "nor in checkpoints/last/pretrained_model), nor another learned part (rl.json, "
            "planner.json, residual.json, skill.json, skill_rl.json, perception.json)"
        )
    config = read_json_mapping(folder / "config.json", "a LeRobot policy's config")
    inputs = config.get("input_features")
    return KINDS["skill" if isinstance(inputs, dict) and "observation.skill" in inputs
                 else "policy"]  # fmt: skip


def kind_of(path: str | Path) -> Kind | None:
    """:func:`detect`'s kind, or None where ``path`` is no learned part (for a caller that
    lets the kind's own checker say what is wrong)."""
    try:
        return detect(path)
    except InputError:
        return None


def require(path: str | Path, *names: str, role: str) -> Kind:
    """:func:`detect`, refused in one line when the kind is none of ``names`` (``role``
    says what the caller runs it as, e.g. "motion.skills")."""
    kind = detect(path)
    if kind.name not in names:
        wanted = " or ".join(KINDS[n].what for n in names)
        raise InputError(f"{path}: {kind.what}, not {wanted} ({role})")
    return kind


def check(path: str | Path, *names: str, role: str, **needs):
    """Check the folder at ``path`` as its kind checks itself, after :func:`require`."""
    kind = require(path, *names, role=role)
    return load_attribute(kind.check, kind.name)(Path(path), **needs)


def load(path: str | Path, *names: str, role: str, **options):
    """Load the folder at ``path`` with its kind's one loader, after :func:`require`."""
    kind = require(path, *names, role=role)
    return load_attribute(kind.load, kind.name)(Path(path), **options)


def describe(path: str | Path) -> str:
    """One phrase for the learned thing at ``path`` (a run's ``layers``)."""
    kind = detect(path)
    return load_attribute(kind.describe, kind.name)(Path(path))


def _kinds_said() -> str:
    return ("rl.json (RL), planner.json (a learned planner), residual.json (a residual), "
            "skill.json (a skill that never sees the arm), skill_rl.json (one with an RL "
            "residual), perception.json (learned eyes), or a LeRobot checkpoint: "
            "config.json and model.safetensors")  # fmt: skip


__all__ = [
    "KINDS",
    "SKILL_KINDS",
    "Kind",
    "check",
    "describe",
    "detect",
    "kind_of",
    "load",
    "require",
]
