"""The project's own LeRobot policy type, ``cake_mlp``: registered with LeRobot, relative
joint targets, its own standardisation with floored spreads, saved with its weights."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from cake_drake.learning.policies.lerobot_checkpoint import lerobot_temporaries
from cake_drake.learning.policies.mlp.configuration_mlp import CakeMLPConfig
from cake_drake.learning.policies.mlp.modeling_mlp import CakeMLPPolicy
from tests.helpers import ROOT


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
    # LeRobot's config reader leaves a tmp*.json a read: the loader's own folder takes it.
    with lerobot_temporaries():
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
    with pytest.raises(ValueError, match="sees the cubes or reads their poses, not both"):
        CakeMLPPolicy(config)


# --- a policy that sees ------------------------------------------------------------------


def seeing(**kw) -> CakeMLPPolicy:
    """A cake_mlp that reads the joints, two cameras of different sizes and the goal."""
    from lerobot.configs.types import FeatureType, PolicyFeature

    inputs = {
        "observation.state": PolicyFeature(FeatureType.STATE, (8,)),
        "observation.goal": PolicyFeature(FeatureType.STATE, (156,)),
        "observation.images.scene": PolicyFeature(FeatureType.VISUAL, (3, 40, 48)),
        "observation.images.wrist": PolicyFeature(FeatureType.VISUAL, (3, 32, 32)),
    }
    outputs = {"action": PolicyFeature(FeatureType.ACTION, (8,))}
    config = CakeMLPConfig(input_features=inputs, output_features=outputs, device="cpu", **kw)
    return CakeMLPPolicy(config)


def camera_batch(n=3, steps=2, seed=2):
    g = torch.Generator().manual_seed(seed)
    return {
        "observation.state": torch.randn(n, steps, 8, generator=g),
        "observation.goal": torch.zeros(n, steps, 156),
        "observation.images.scene": torch.rand(n, steps, 3, 40, 48, generator=g),
        "observation.images.wrist": torch.rand(n, steps, 3, 32, 32, generator=g),
        "action": torch.randn(n, 10, 8, generator=g),
    }


def test_a_policy_that_sees_reads_no_pose_and_each_cameras_latest_frame():
    p = seeing(n_obs_steps=2)
    assert "observation.environment_state" not in p.config.input_features
    assert set(p.vision) == {"scene", "wrist"}
    b = camera_batch()
    p.eval()
    chunk = p.predict_action_chunk(b)
    assert chunk.shape == (3, 10, 8) and torch.isfinite(chunk).all()
    older = {k: v.clone() for k, v in b.items()}
    older["observation.images.scene"][:, 0] = 0.0  # the frame before: not read
    assert torch.equal(p.predict_action_chunk(older), chunk)
    newer = {k: v.clone() for k, v in b.items()}
    newer["observation.images.wrist"][:, -1] = 1.0 - newer["observation.images.wrist"][:, -1]
    assert not torch.allclose(p.predict_action_chunk(newer), chunk)
    keypoints = p.vision["scene"](torch.rand(2, 3, 40, 48))
    assert keypoints.shape == (2, 2 * p.config.vision_keypoints)
    assert keypoints.abs().max() <= 1.0  # expected image coordinates in [-1, 1]


def test_augmentation_moves_the_images_and_not_the_labels():
    from cake_drake.learning.policies.mlp.network import random_shift

    images = torch.rand(16, 3, 20, 24)
    torch.manual_seed(0)
    moved = random_shift(images, 3)
    assert moved.shape == images.shape and not torch.equal(moved, images)
    assert torch.equal(random_shift(images, 0), images)
    for k in range(16):  # each image is its own whole-pixel translate, border repeated
        padded = torch.nn.functional.pad(images[k : k + 1], (3, 3, 3, 3), mode="replicate")[0]
        assert any(
            torch.equal(moved[k], padded[:, dy : dy + 20, dx : dx + 24])
            for dy in range(7)
            for dx in range(7)
        )
    p = seeing(n_obs_steps=2, crop_shift=4)
    b = camera_batch()
    labels = b["action"].clone()
    p.train()
    torch.manual_seed(1)
    first = p.forward(b)[0]
    torch.manual_seed(2)
    second = p.forward(b)[0]
    assert not torch.equal(first, second)  # the images were moved, differently each time
    assert torch.equal(b["action"], labels)  # the labels were not
    p.eval()
    assert torch.equal(p.predict_action_chunk(b), p.predict_action_chunk(b))  # not in acting


def test_a_policy_that_sees_loads_without_lerobot_as_it_was_trained(tmp_path):
    from cake_drake.learning.policies.mlp.network import load

    p = seeing(n_obs_steps=2, vision_keypoints=8)
    p.save_pretrained(tmp_path)
    network = load(tmp_path)
    b = camera_batch()
    p.eval()
    assert torch.equal(network.predict_action_chunk(b), p.predict_action_chunk(b))
    now = {k: v[:1, -1] for k, v in b.items() if k.startswith("observation.")}
    assert torch.equal(network.select_action(now), p.select_action(now))


# --- acting without torch ----------------------------------------------------------------


@pytest.mark.parametrize("n_obs_steps", [1, 2])
def test_numpy_acting_is_the_networks_arithmetic(tmp_path, n_obs_steps):
    from cake_drake.learning.policies.mlp.acting import NumpyChunks, load

    p = policy(n_obs_steps=n_obs_steps, chunk_size=4, n_action_steps=3)
    p.save_pretrained(tmp_path)
    acting = load(tmp_path, "cpu")
    assert isinstance(acting, NumpyChunks)
    b = batch(n=5)
    if n_obs_steps > 1:  # (B, T, D): the history
        b = {k: torch.stack([v, v.flip(0)], dim=1) for k, v in b.items()}
    want = p.predict_action_chunk(b).numpy()
    got = acting.predict_action_chunk({k: v.numpy() for k, v in b.items()})
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)
    p.reset()
    for k in range(7):  # the queue and the history: the same actions, step after step
        now = batch(n=1, seed=10 + k)
        np.testing.assert_allclose(
            acting.select_action({key: v.numpy() for key, v in now.items()}),
            p.select_action(now).numpy(),
            rtol=1e-5,
            atol=1e-5,
        )


def test_temporal_ensembling_averages_every_live_chunks_prediction_for_the_step(tmp_path):
    """ACT's temporal ensembling: a chunk predicted at every step, the action the mean of
    every chunk still covering this step, weighted exp(-m * i) with i = 0 the oldest."""
    from cake_drake.learning.policies.mlp.acting import NumpyChunks, load

    p = policy(n_obs_steps=1, chunk_size=4, n_action_steps=2)
    p.save_pretrained(tmp_path)
    m = 0.5
    acting = load(tmp_path, "cpu", ensemble=m)
    plain = NumpyChunks(tmp_path)
    frames = [{k: v.numpy() for k, v in batch(n=1, seed=20 + k).items()} for k in range(7)]
    chunks = [plain.predict_action_chunk(f)[0] for f in frames]
    for t, frame in enumerate(frames):
        live = [(s, chunks[s][t - s]) for s in range(max(0, t - 3), t + 1)]  # oldest first
        weights = np.exp(-m * np.arange(len(live)))
        want = sum(w * a for w, (_, a) in zip(weights, live, strict=True)) / weights.sum()
        np.testing.assert_allclose(acting.select_action(frame)[0], want, rtol=1e-5, atol=1e-6)
    acting.reset()  # a new action: nothing of the last one's chunks
    np.testing.assert_allclose(acting.select_action(frames[3])[0], chunks[3][0], rtol=1e-5,
                               atol=1e-6)  # fmt: skip
    with pytest.raises(ValueError, match="temporal ensembling acts in NumPy"):
        load(tmp_path, "cuda", ensemble=m)


def test_a_run_with_the_shipped_state_policy_imports_no_torch(tmp_path):
    import subprocess
    import sys

    root = ROOT
    code = (
        "import sys\n"
        "from cake_drake.commands.run import main_run\n"
        "code = main_run(['--scenario', sys.argv[1], '--name', 'learned_stack2', '--out', "
        "sys.argv[2], '--quiet'])\n"
        "print(code, 'torch' in sys.modules)\n"
    )
    r = subprocess.run(
        [sys.executable, "-c", code, str(root / "models/scenarios/learning.yaml"),
         str(tmp_path / "out")],
        cwd=root, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert r.stdout.split()[-2:] == ["0", "False"], r.stdout + r.stderr
