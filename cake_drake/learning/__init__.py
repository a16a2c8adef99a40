"""The learned layer's home, above the pipeline: episodes and what is learned from them.

Nothing below this package imports it; the Diagram's own vocabulary (action spaces,
observations) stays in :mod:`cake_drake.policy`, and what runs inside the Diagram (a
learned skill's system, the dynamic residual) in :mod:`cake_drake.systems` and
:mod:`cake_drake.dynamic`. Here, by room:

- :mod:`~cake_drake.learning.envs`: the environments. ``CakeDrake/Stack-v0`` (``env``:
  the Gymnasium env over the same Diagram a run builds), its reward terms (``rewards``)
  and its registration as LeRobot's environment type ``cake_drake`` (``lerobot_env``).
- :mod:`~cake_drake.learning.data`: LeRobot recordings. The dataset's format, written and
  read by lerobot itself (``dataset``), recording and replaying demonstrations
  (``recording``), and the batches LeRobot's loop trains on, read once into memory
  (``batches``).
- :mod:`~cake_drake.learning.policies`: what acts. A checkpoint folder of either kind as a
  policy (``checkpoint``: LeRobot's, ``lerobot_checkpoint``, or an RL training's, ``rl``),
  a learned skill (``skills``), the classical cake as a closed-loop teacher (``expert``)
  and the project's own policy type ``cake_mlp`` (``mlp``).
- :mod:`~cake_drake.learning.training`: what learns. Imitation through LeRobot's own loop
  (``train``), DAgger (``dagger``), RL with Stable-Baselines3 (``rl``), the dynamic
  residual's least-squares fit (``residual``) and the learned planner (``planner``).
- here: an episode through the env, a policy acting or recorded actions replayed
  (``rollout``); a policy's success rate with its interval (``evaluation``); episodes
  spread over processes or Ray (``parallel``).

The modules at this package's top besides those (``checkpoint``, ``expert``, ``skills``,
``lerobot_env``, ``mlp.configuration_mlp``) are the paths that files name (scenarios,
recordings, LeRobot's plug-in), kept as thin re-exports of the modules above.
"""
