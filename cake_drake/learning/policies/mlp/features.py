"""What a ``cake_mlp`` reads, by LeRobot's feature names: torch-free, shared by the network
(:mod:`cake_drake.learning.policies.mlp.network`) and its NumPy acting
(:mod:`cake_drake.learning.policies.mlp.acting`)."""

from __future__ import annotations

#: The arm's joints in a joint_position action (the gripper's width follows).
ARM = 7
OBS_STATE = "observation.state"
OBS_ENV_STATE = "observation.environment_state"
OBS_SKILL = "observation.skill"
OBS_GOAL = "observation.goal"
OBS_IMAGES = "observation.images."
ACTION = "action"
#: The inputs it reads besides ``observation.state``, and their buffers' names: the
#: whole-task policy reads the cubes and the goal, a learned skill its ground action, a
#: policy that sees the goal alone (no pose) beside its cameras.
EXTRA_INPUTS = {OBS_ENV_STATE: "env", OBS_SKILL: "skill", OBS_GOAL: "goal"}


def _shape(feature) -> tuple[int, ...]:
    return tuple(int(n) for n in (feature["shape"] if isinstance(feature, dict) else feature.shape))


def input_sizes(features: dict) -> dict[str, int]:
    """The inputs a ``cake_mlp`` reads, in the order it reads them, and their sizes, from a
    config's ``input_features`` (LeRobot's objects or a config.json's dicts)."""

    sizes = {OBS_STATE: _shape(features[OBS_STATE])[0]} if OBS_STATE in features else {}
    sizes.update({k: _shape(features[k])[0] for k in EXTRA_INPUTS if k in features})
    return sizes


def camera_shapes(features: dict) -> dict[str, tuple[int, int, int]]:
    """The cameras a ``cake_mlp`` sees, by feature key, and their (channels, height,
    width), sorted by name (the order their keypoints are read in)."""
    return {k: _shape(features[k]) for k in sorted(features) if k.startswith(OBS_IMAGES)}
