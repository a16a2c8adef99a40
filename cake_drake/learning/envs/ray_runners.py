"""Environment runners on Ray: Stable-Baselines3's learner fed by environments on a cluster.

:class:`RayVecEnv` is a Stable-Baselines3 ``VecEnv`` whose environments each live in a
Ray actor (one CPU each), on this machine's local instance or on every node of a
cluster joined by address (:class:`cake_drake.sweeps.RayCluster`, the sweeps' engine).
The learner stays where it is (one process, its CPU or GPU); each step sends every
runner its action and waits for their answers together, so a step costs the slowest
runner's simulation plus a round trip. The runners reset themselves at an episode's end
and hand back the last observation as ``terminal_observation``, as Stable-Baselines3's
own vectorised environments do; the learner, its recipe, its reward and its folder are
the same as on one machine.

Why not RLlib: the learner, the recipe's algorithms (PPO, SAC), the checkpoint
(``model.zip``) and the residual's zero start would all change with it; what RL needs
beyond one machine here is more simulators, not another learner.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cake_drake.errors import ExecutionError


class _Runner:
    """One environment in a Ray actor."""

    def __init__(self, factory) -> None:
        import torch  # a base policy's forward pass: one thread, the actor's one CPU

        torch.set_num_threads(1)
        self.env = factory()

    def spaces(self):
        return self.env.observation_space, self.env.action_space, self.env.metadata

    def reset(self, seed, options):
        return self.env.reset(seed=seed, **({"options": options} if options else {}))

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        info = dict(info)
        info["TimeLimit.truncated"] = bool(truncated and not terminated)
        reset_info = None
        if terminated or truncated:
            info["terminal_observation"] = obs
            obs, reset_info = self.env.reset()
        return obs, float(reward), bool(terminated or truncated), info, reset_info

    def get(self, name: str):
        return self.env.get_wrapper_attr(name)

    def set(self, name: str, value) -> None:
        setattr(self.env, name, value)

    def call(self, name: str, args, kwargs):
        return self.env.get_wrapper_attr(name)(*args, **kwargs)

    def wrapped(self, cls) -> bool:
        from stable_baselines3.common import env_util

        return env_util.is_wrapped(self.env, cls)

    def close(self) -> None:
        self.env.close()


def ray_vec_env(factory, runners: int, cluster):
    """A :class:`RayVecEnv` of ``runners`` environments made by ``factory`` on ``cluster``."""
    from stable_baselines3.common.vec_env import VecEnv

    class RayVecEnv(VecEnv):
        """``runners`` copies of ``factory()``'s environment, each in a Ray actor."""

        def __init__(self) -> None:
            self.cluster = cluster
            self.ray = ray = cluster.start()
            self.runners = []
            try:  # an interrupt while the runners start stops Ray as close() does
                actor = ray.remote(num_cpus=1, max_restarts=0)(_Runner)
                self.runners = [actor.remote(factory) for _ in range(runners)]
                obs_space, act_space, metadata = self._get([self.runners[0].spaces.remote()])[0]
            except BaseException:
                self._stop()
                raise
            super().__init__(runners, obs_space, act_space)
            self.metadata = metadata
            self._pending: list = []

        def _get(self, refs: list) -> list:
            try:
                return self.ray.get(refs)
            except self.ray.exceptions.RayError as e:
                first = (str(e).strip().splitlines() or [type(e).__name__])[0]
                raise ExecutionError(f"an environment runner on Ray failed: {first}") from None

        def _indices(self, indices) -> list[int]:
            if indices is None:
                return list(range(self.num_envs))
            return [indices] if isinstance(indices, int) else list(indices)

        def reset(self):
            refs = [r.reset.remote(self._seeds[k], self._options[k])
                    for k, r in enumerate(self.runners)]  # fmt: skip
            answers = self._get(refs)
            self.reset_infos = [info for _, info in answers]
            self._reset_seeds()
            self._reset_options()
            return np.stack([obs for obs, _ in answers])

        def step_async(self, actions: np.ndarray) -> None:
            self._pending = [r.step.remote(a) for r, a in zip(self.runners, actions, strict=True)]

        def step_wait(self):
            answers, self._pending = self._get(self._pending), []
            obs = np.stack([a[0] for a in answers])
            rewards = np.array([a[1] for a in answers], np.float32)
            dones = np.array([a[2] for a in answers], bool)
            infos = [a[3] for a in answers]
            for k, a in enumerate(answers):
                if a[4] is not None:
                    self.reset_infos[k] = a[4]
            return obs, rewards, dones, infos

        def close(self) -> None:
            try:
                if self.runners:
                    self._get([r.close.remote() for r in self.runners])
            finally:
                self._stop()

        def _stop(self) -> None:
            for r in self.runners:
                self.ray.kill(r)
            self.runners = []
            self.cluster.stop()

        def get_attr(self, attr_name: str, indices=None) -> list[Any]:
            return self._get([self.runners[k].get.remote(attr_name)
                              for k in self._indices(indices)])  # fmt: skip

        def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
            self._get([self.runners[k].set.remote(attr_name, value)
                       for k in self._indices(indices)])  # fmt: skip

        def env_method(self, method_name: str, *args, indices=None, **kwargs) -> list[Any]:
            return self._get([self.runners[k].call.remote(method_name, args, kwargs)
                              for k in self._indices(indices)])  # fmt: skip

        def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
            return self._get([self.runners[k].wrapped.remote(wrapper_class)
                              for k in self._indices(indices)])  # fmt: skip

    return RayVecEnv()


__all__ = ["ray_vec_env"]
