"""The environments a policy learns and is measured in.

``CakeDrake/Stack-v0`` (:mod:`.env`, registered by :mod:`cake_drake.gym`) is a Gymnasium
face over the Diagram a run builds (``CakeDrake/Skill-v0``, one ground action of a
learned skill an episode, lives with the skills: :mod:`cake_drake.learning.skills.env`);
:mod:`.ray_runners` puts
environments on Ray for a learner elsewhere; :mod:`.rewards` holds its reward terms; and
:mod:`.lerobot_env` registers the learning tasks as LeRobot's environment type
``cake_drake`` (``lerobot-eval --env.type=cake_drake``). An environment's wrappers for
one learner (RL's view of it) live with that learner's training.
"""
