"""Registers cake_drake with LeRobot: its learning tasks as the environment type cake_drake,
and its state policy as the policy type cake_mlp (so lerobot-eval runs its checkpoints)."""

import cake_drake.learning.envs.lerobot_env  # noqa: F401 - registers the environment type
import cake_drake.learning.policies.mlp.configuration_mlp  # noqa: F401 - registers cake_mlp
