"""The perception layer: where the cake's knowledge of the cubes comes from.

``truth`` reads the simulator's own body poses (no system at all: the plant's port, as
every run before this layer); ``depth``, ``oracle`` and ``learned`` are a
:class:`CubeEstimator` on cameras of their own, answering the plant's ``body_poses``
shape. :mod:`cake_drake.diagram` wires whichever port the scenario names into every
consumer; the verdict and the error log keep reading the truth.

- ``settings.py``: the scenario's ``perception:`` section, the default cameras
- ``cloud.py``: depth to points (the principal-point convention), colour segmentation, noise
- ``fit.py``: a cube's pose from its points (a footprint start, ICP on the cube's faces)
- ``learned.py``: the learned eyes, a point network answering a cube's pose from the
  same points (its checkpoint's one checked reader)
- ``estimator.py``: the Diagram's system, the belief carried between frames
- ``report.py``: the error log, measured against the truth after the run
"""

from cake_drake.perception.settings import ESTIMATORS, NOISE_MODELS, DepthNoise, Perception

__all__ = ["ESTIMATORS", "NOISE_MODELS", "DepthNoise", "Perception"]
