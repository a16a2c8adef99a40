"""What acts: every learned or teaching policy a run, an episode or DAgger can call.

:mod:`.checkpoint` turns a checkpoint folder of either kind into a policy plug-in (made,
checked and described): a LeRobot checkpoint (:mod:`.lerobot_checkpoint`, its checked
reader and the adapter that acts with it) or an RL training's folder (:mod:`.rl`).
:mod:`.skills` is a learned skill as the geometric layer's skill (:mod:`.relative_skill`
one that never sees the arm, :mod:`.skill_rl` one with an RL residual), :mod:`.expert` the
classical cake closed at every step (the teacher), and :mod:`.mlp` the project's own
policy type ``cake_mlp``. How they were trained lives in :mod:`cake_drake.learning.training`.
"""
