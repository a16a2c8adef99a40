"""What acts: every learned or teaching policy a run, an episode or DAgger can call.

:mod:`.checkpoint` turns a checkpoint folder of either kind into a policy plug-in (made,
checked and described): a LeRobot checkpoint (:mod:`.lerobot_checkpoint`, its checked
reader and the adapter that acts with it) or an RL training's folder (:mod:`.rl`).
:mod:`.expert` is the classical cake closed at every step (the teacher), and :mod:`.mlp`
the project's own policy type ``cake_mlp``. How they were trained lives in
:mod:`cake_drake.learning.training`; the learned skills, with their training and
environment, in :mod:`cake_drake.learning.skills`.
"""
