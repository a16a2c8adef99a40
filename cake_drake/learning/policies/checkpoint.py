"""A checkpoint folder as a policy plug-in, of whichever kind it is.

A folder is an RL training's (it holds ``rl.json``: :mod:`cake_drake.learning.policies.rl`)
or a LeRobot checkpoint (:mod:`cake_drake.learning.policies.lerobot_checkpoint`). The
functions here tell which, and check, make and describe it through that kind's module:
what ``evaluate DIR``, a run's ``reference: !Policy {checkpoint: DIR}`` and the Gym env's
policy plug-in call (scenarios name them as ``cake_drake.learning.checkpoint:make``,
``:check_folder`` and ``:describe``).
"""

from __future__ import annotations

from pathlib import Path

from cake_drake import artifacts
from cake_drake.errors import InputError
from cake_drake.learning.policies import lerobot_checkpoint, rl
from cake_drake.learning.policies.lerobot_checkpoint import (
    CheckpointPolicy,
    camera_features,
    model_folder,
    read_checkpoint,
)

RL_PIP = "pip install -e '.[rl]'"


def require_rl_packages(what: str) -> None:
    """Refuse in one line (with the line that installs them) where Stable-Baselines3 or
    the Gymnasium it runs on is not installed; ``what`` needs them."""
    try:
        import stable_baselines3  # noqa: F401 - only whether it is there (it imports torch)
    except ModuleNotFoundError as e:
        raise InputError(f"{what} needs {e.name}, which is not installed: {RL_PIP}") from None


def _rl(path) -> bool:
    """Whether ``path`` is an RL training's folder (its kind, by :mod:`cake_drake.artifacts`);
    refused in one line there where Stable-Baselines3 is not installed (it acts with it)."""
    kind = artifacts.kind_of(path)
    if kind is None or kind.name != "rl":
        return False
    require_rl_packages(f"{path}: an RL folder")
    return True


def check_folder(path: Path, action_space: str, device: str = "auto", cameras=None) -> Path:
    """Refuse, before anything is built, a folder that cannot run as a whole-task policy
    here (:func:`cake_drake.learning.policies.lerobot_checkpoint.check_folder`, or for an
    RL training's folder :func:`cake_drake.learning.policies.rl.check_folder`); the model's
    folder (an RL folder: itself)."""
    artifacts.require(path, "policy", "rl", role="reference: !Policy {checkpoint}")
    if _rl(path):
        rl.check_folder(path, action_space, device, cameras)
        return Path(path)
    return lerobot_checkpoint.check_folder(path, action_space, device, cameras)


def make(path: str, device: str = "auto"):
    """A checkpoint folder as a policy plug-in (``evaluate DIR``, ``!Policy {checkpoint}``):
    a LeRobot checkpoint, or an RL training's folder
    (:class:`cake_drake.learning.policies.rl.RlPolicy`)."""
    return rl.RlPolicy(path, device) if _rl(path) else CheckpointPolicy(path, device)


def sees(path: Path) -> dict[str, tuple[int, ...]]:
    """The cameras the checkpoint at ``path`` reads (an RL residual: its base's)."""
    if _rl(path):
        return rl.base_cameras(path)
    return camera_features(read_checkpoint(model_folder(path)))


def is_skill_folder(path: Path) -> bool:
    """Whether the checkpoint at ``path`` is a learned skill's (its kind, by
    :mod:`cake_drake.artifacts`)."""
    kind = artifacts.kind_of(path)
    return kind is not None and kind.name in artifacts.SKILL_KINDS


def describe(path: Path) -> str:
    """What learned the whole-task policy at ``path``, as a run's ``layers`` says it."""
    return artifacts.describe(path)
