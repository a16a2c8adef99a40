"""A policy plug-in: the classical cake, as a policy a learned one can be compared with.

At ``reset`` it plans the task and computes the classical run's joint reference (the
symbolic and geometric layers, run once ahead in a simulation of its own, with moves
slowed so that one 10 Hz step never asks for more than a ``ee_delta`` step allows). At
each step it answers in the run's action space with where that reference is one step
later:

- ``joint_position``: the reference's joints and gripper width;
- ``ee_delta``: the move from the measured grasp frame to the reference's, and the gripper;
- ``joint_chunk``: the next H rows of joint targets.

It says done once the reference has ended. Use it:
``reference: !Policy {factory: examples.expert_policy:make, action_space: ee_delta}``.
"""

from __future__ import annotations

import copy

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from cake_drake.geometric.ik import Kinematics
from cake_drake.policy.spaces import EE_STEP, GRIPPER_MAX
from cake_drake.scenario import Planned


class ExpertPolicy:
    """See the module's docstring. ``slow`` scales the classical moves' speed limits."""

    def __init__(self, slow: float = 0.35) -> None:
        self.slow = slow
        self.kin = Kinematics()

    def reset(self, task, seed: int) -> None:
        from cake_drake.pipeline import run

        scenario = copy.deepcopy(task.scenario)
        scenario.reference = Planned()
        scenario.cameras = []
        # The world the environment built (its seed places the cubes): plan in that one.
        timing = scenario.motion.timing
        timing.velocity_fraction *= self.slow
        timing.acceleration_fraction *= self.slow
        result = run(scenario, write=False)
        logs = result.execution.logs
        self.t, self.q = logs.t, logs.q_d
        self.width = 2 * logs.fingers_d.reshape(len(logs.t), -1)[:, 0]
        self.end = float(self.t[-1])
        self.space, self.rate = task.action_space, task.rate_hz
        self.horizon = int((task.options or {}).get("horizon", 10))
        self.execute = int((task.options or {}).get("execute", self.horizon))
        self.steps = 0

    def reference(self, t: float) -> tuple[np.ndarray, float]:
        """Joints and gripper width of the classical reference at ``t`` (held at its end)."""
        q = np.array([np.interp(t, self.t, self.q[:, j]) for j in range(7)])
        return q, float(np.interp(t, self.t, self.width))

    def act(self, observation: dict):
        """``observation``: the policy slot's (``observation.ee_pose``) or the Gymnasium
        environment's (``state``, whose last 7 numbers are the grasp frame's pose)."""
        step = self.steps  # the env's steps so far (a chunk is `execute` of them)
        self.steps += self.execute if self.space == "joint_chunk" else 1
        if self.space != "ee_delta":
            t = (step + 1) / self.rate  # where the reference is when this step's hold ends
            if t > self.end + 1.0 / self.rate:
                return None, True
            if self.space == "joint_chunk":
                rows = [self.reference((step + 1 + i) / self.rate) for i in range(self.horizon)]
                return np.array([[*q, w] for q, w in rows])
            q, width = self.reference(t)
            return np.r_[q, width]
        # ee_delta: a step is a bounded move from where the hand is measured, so the
        # reference's clock waits while the hand is behind it (it catches up first).
        pose = np.asarray(
            observation["observation.ee_pose"]
            if "state" not in observation
            else observation["state"][-7:],
            float,
        )
        X_now = RigidTransform(RotationMatrix(_quaternion(pose[3:])), pose[:3])
        if step == 0:
            self.tau = 0.0
        X_tau = self.kin.pose(self.reference(self.tau)[0])
        behind = np.linalg.norm(X_tau.translation() - X_now.translation())
        turned = X_tau.rotation().multiply(X_now.rotation().inverse()).ToAngleAxis().angle()
        if behind < 0.01 and turned < 0.05:
            self.tau += 1.0 / self.rate
        if self.tau > self.end + 1.0 / self.rate:
            return None, True
        q, width = self.reference(self.tau)
        X_ref = self.kin.pose(q)
        d_rot = X_ref.rotation().multiply(X_now.rotation().inverse())
        delta = np.r_[X_ref.translation() - X_now.translation(), RollPitchYaw(d_rot).vector()]
        return np.r_[np.clip(delta, -EE_STEP, EE_STEP), min(width / GRIPPER_MAX, 1.0)]


def _quaternion(wxyz):
    from pydrake.common.eigen_geometry import Quaternion

    return Quaternion(wxyz / np.linalg.norm(wxyz))


def make(**options) -> ExpertPolicy:
    return ExpertPolicy(**options)
