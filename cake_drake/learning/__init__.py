"""The learned layer's home, above the pipeline: episodes and what is learned from them.

The Gym environment, rollouts, the classical cake as a closed-loop teacher, LeRobot
recordings, training through LeRobot's own loop, the checkpoint adapter, evaluation and
DAgger. Nothing below this package imports it; the Diagram's own vocabulary (action
spaces, observations) stays in :mod:`cake_drake.policy`.
"""
