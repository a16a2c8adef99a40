"""``CakeDrake/Stack-v0`` and ``CakeDrake/Skill-v0``, registered with Gymnasium: importing
this module registers them.

    import gymnasium
    env = gymnasium.make("cake_drake.gym:CakeDrake/Stack-v0", control_mode="ee_delta")
    env = gymnasium.make("cake_drake.gym:CakeDrake/Skill-v0", blocks=(3, 6))

The environments themselves are :class:`cake_drake.learning.envs.env.StackEnv` (a whole
Blocksworld task) and :class:`cake_drake.learning.skills.env.SkillEnv` (one ground
action of a learned skill).
"""

import gymnasium

from cake_drake.learning.envs.env import HeldAction, StackEnv

ENV_ID = "CakeDrake/Stack-v0"
SKILL_ENV_ID = "CakeDrake/Skill-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="cake_drake.learning.envs.env:StackEnv")
if SKILL_ENV_ID not in gymnasium.registry:
    gymnasium.register(id=SKILL_ENV_ID, entry_point="cake_drake.learning.skills.env:SkillEnv")

__all__ = ["ENV_ID", "SKILL_ENV_ID", "HeldAction", "StackEnv"]
