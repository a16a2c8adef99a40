"""A policy plug-in: the classical cake as a policy a learned one can be compared with.

The expert is :mod:`cake_drake.learning.policies.expert`, the classical cake closed at every
step: it reads facts from the measured cube poses, keeps its plan while the world is
what the plan expects and plans again when it is not, and moves the hand from where it
is along the classical layer's waypoints and IK, timed for the policy's rate. Use it:
``reference: !Policy {factory: examples.expert_policy:make, action_space: ee_delta}``.
"""

from __future__ import annotations

from cake_drake.learning.policies.expert import ClosedLoopExpert


def make(slow: float = 0.35) -> ClosedLoopExpert:
    """The expert, moving at ``slow`` of the classical speed limits at 10 Hz."""
    return ClosedLoopExpert(slow=slow)
