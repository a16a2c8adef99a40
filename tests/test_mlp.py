"""The project's own LeRobot policy type, ``cake_mlp``: registered with LeRobot, relative
joint targets, its own standardisation with floored spreads, saved with its weights."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from cake_drake.learning.mlp.configuration_mlp import CakeMLPConfig
from cake_drake.learning.mlp.modeling_mlp import CakeMLPPolicy


def features():
    from lerobot.configs.types import FeatureType, PolicyFeature

    return (
        {
            "observation.state": PolicyFeature(FeatureType.STATE, (8,)),
            "observation.environment_state": PolicyFeature(FeatureType.ENV, (240,)),
        },
        {"action": PolicyFeature(FeatureType.ACTION, (8,))},
    )


def stats():
    rng = np.random.default_rng(0)
    env_std = np.zeros(240)  # a zero-padded cube never varies
    env_std[:14] = rng.uniform(0.01, 0.1, 14)
    return {
        "observation.state": {"mean": rng.normal(size=8), "std": rng.uniform(0.1, 1, 8)},
        "observation.environment_state": {"mean": np.zeros(240), "std": env_std},
        "action": {"mean": rng.normal(size=8), "std": rng.uniform(0.1, 1, 8)},
    }


def policy(**kw) -> CakeMLPPolicy:
    inputs, outputs = features()
    config = CakeMLPConfig(input_features=inputs, output_features=outputs, device="cpu", **kw)
    return CakeMLPPolicy(config, dataset_stats=stats())


def batch(n=2, seed=1):
    g = torch.Generator().manual_seed(seed)
    return {
        "observation.state": torch.randn(n, 8, generator=g),
        "observation.environment_state": torch.randn(n, 240, generator=g),
    }


def test_lerobot_finds_the_policy_and_its_processors_by_its_type():
    from lerobot.policies.factory import get_policy_class, make_pre_post_processors

    assert get_policy_class("cake_mlp") is CakeMLPPolicy
    pre, post = make_pre_post_processors(policy().config)
    out = pre({k: v[0] for k, v in batch().items()})
    assert out["observation.state"].shape == (1, 8)  # batched, not normalised: the policy does


def test_joint_targets_are_offsets_from_the_measured_joints():
    p = policy(chunk_size=4, n_action_steps=2)
    torch.nn.init.zeros_(p.net[-1].weight)
    torch.nn.init.zeros_(p.net[-1].bias)
    b = batch()
    chunk = p.predict_action_chunk(b)
    assert chunk.shape == (2, 4, 8)
    # A zero output holds the arm where it is and the gripper at the demonstrations' mean.
    assert torch.allclose(chunk[:, :, :7], b["observation.state"][:, None, :7].expand(2, 4, 7))
    assert torch.allclose(chunk[:, :, 7], torch.full((2, 4), float(p.action_mean[7])))
    absolute = policy(chunk_size=4, n_action_steps=2, relative_joints=False)
    absolute.net.load_state_dict(p.net.state_dict())
    assert torch.allclose(absolute.predict_action_chunk(b), p.action_mean.expand(2, 4, 8))


def test_the_loss_is_zero_on_its_own_prediction_and_ignores_padding():
    p = policy(chunk_size=3, n_action_steps=1)
    b = batch()
    b["action"] = p.predict_action_chunk(b)
    loss, info = p.forward(b)
    assert float(loss.detach()) < 1e-6 and info["l1_loss"] < 1e-6
    b["action"] = b["action"].clone()
    b["action"][:, 2] += 1.0
    b["action_is_pad"] = torch.tensor([[False, False, True]] * 2)
    assert float(p.forward(b)[0].detach()) < 1e-6  # the padded step past the episode's end
    b["action_is_pad"][:, 2] = False
    assert float(p.forward(b)[0].detach()) > 0.1


def test_a_spread_that_never_varied_is_floored_not_divided_by():
    p = policy(min_std=0.01)
    assert float(p.env_std.min()) == pytest.approx(0.01)
    b = batch()
    b["observation.environment_state"][:, 200] = 1.0  # a number no demonstration changed
    assert torch.isfinite(p.predict_action_chunk(b)).all()


def test_the_queue_serves_n_action_steps_then_asks_again():
    p = policy(chunk_size=6, n_action_steps=3)
    b = {k: v[:1] for k, v in batch().items()}
    chunk = p.predict_action_chunk(b)[0]
    got = [p.select_action(b)[0] for _ in range(4)]
    for k in range(3):
        assert torch.equal(got[k], chunk[k])
    assert torch.equal(got[3], chunk[0])  # the same observation again: a new chunk
    p.reset()
    assert not p._queue


def test_statistics_travel_with_the_weights(tmp_path):
    p = policy()
    p.save_pretrained(tmp_path)
    loaded = CakeMLPPolicy.from_pretrained(tmp_path)  # no dataset statistics given
    b = batch()
    assert torch.equal(loaded.predict_action_chunk(b), p.predict_action_chunk(b))


def test_a_configuration_that_cannot_work_is_refused():
    with pytest.raises(ValueError, match="n_action_steps 5: 1 to chunk_size"):
        CakeMLPConfig(chunk_size=4, n_action_steps=5)
    from lerobot.configs.types import FeatureType, PolicyFeature

    inputs, outputs = features()
    inputs["observation.images.scene"] = PolicyFeature(FeatureType.VISUAL, (3, 96, 96))
    config = CakeMLPConfig(input_features=inputs, output_features=outputs)
    with pytest.raises(ValueError, match="reads numbers only"):
        CakeMLPPolicy(config)
