"""``CakeDrake/Stack-v0``, registered with Gymnasium: importing this module registers it.

    import gymnasium
    env = gymnasium.make("cake_drake.gym:CakeDrake/Stack-v0", control_mode="ee_delta")

The environment itself is :class:`cake_drake.learning.envs.env.StackEnv`.
"""

import gymnasium

from cake_drake.learning.envs.env import HeldAction, StackEnv

ENV_ID = "CakeDrake/Stack-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="cake_drake.learning.envs.env:StackEnv")

__all__ = ["ENV_ID", "HeldAction", "StackEnv"]
