"""What learns: each learned kind's training, writing the folder its policy reads back.

:mod:`.train` runs LeRobot's own loop (imitation), :mod:`.dagger` rounds of DAgger over
it, :mod:`.rl` Stable-Baselines3's PPO or SAC (the RL policy's folder), :mod:`.residual`
the dynamic layer's residual by least squares, :mod:`.planner` the learned planner
(:mod:`.planner_reward` from the goal's reward alone), :mod:`.perception` the learned
eyes' point network. The learned skills' trainings
live with them (:mod:`cake_drake.learning.skills`).
What the results act with lives in :mod:`cake_drake.learning.policies` (and, for the
residual, the planner and the eyes, in their layers: :mod:`cake_drake.dynamic.residual`,
:mod:`cake_drake.symbolic.learned`, :mod:`cake_drake.perception.learned`).
"""
