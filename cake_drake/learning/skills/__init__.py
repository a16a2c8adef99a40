"""The learned geometric layer: skills that do one ground action from what the skill
reads, in one folder. The Diagram's system that asks them is
:class:`cake_drake.systems.skills.LearnedSkills`, beside the other systems, and the
shield's steps around them are :mod:`cake_drake.policy.shield` (both below this layer).

- :mod:`.checkpoints`: which skill a folder holds, checked and loaded (``motion.skills``,
  ``evaluate``); ``cake_drake.learning.skills:make`` is the path scenarios name.
- :mod:`.relative`: the skill that never sees the arm (``skill.json``, its network and
  what it reads); :mod:`.train_relative` trains it.
- :mod:`.residual`: a relative skill with an RL residual (``skill_rl.json``);
  :mod:`.train_residual` trains it in ``CakeDrake/Skill-v0``.
- :mod:`.env`: ``CakeDrake/Skill-v0``, one ground action an episode; :mod:`.starts`, its
  start pools.
"""

from cake_drake.learning.skills.checkpoints import check_folder, describe, make, under_expert

__all__ = ["check_folder", "describe", "make", "under_expert"]
