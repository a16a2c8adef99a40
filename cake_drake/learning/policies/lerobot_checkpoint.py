"""A LeRobot checkpoint folder: its one checked reader, and the adapter that acts with it.

:func:`read_checkpoint` reads and checks a checkpoint's ``config.json`` (against its
weights' shapes too); :func:`check_folder` refuses, before anything is built, a folder
that cannot run as a whole-task policy here.

:class:`CheckpointPolicy` loads a LeRobot ``PreTrainedPolicy`` and its pre- and
post-processors from a folder (one written by ``python -m cake_drake.train``, or any
LeRobot checkpoint folder), resets its action queue at each episode's ``reset``, and at
each ``act`` maps the observation (the slot's ``observation.*`` keys, or the Gym env's
``state`` / ``environment_state`` / ``images``) onto the features the policy was trained
on, runs it on the CPU or a GPU, and answers with one action of the space it was trained
in. The same adapter serves ``evaluate``, a run (``reference: !Policy {checkpoint: DIR}``),
the Gym env (``make(path=DIR)`` as any policy plug-in) and an RL residual's frozen base;
which kind of checkpoint a folder is (LeRobot's or an RL training's) is told by
:mod:`cake_drake.learning.policies.checkpoint`.
"""

from __future__ import annotations

import contextlib
import io
import json
import struct
import tempfile
from pathlib import Path

import numpy as np

from cake_drake import artifacts
from cake_drake.errors import InputError
from cake_drake.formats import read_json_mapping
from cake_drake.learning.data.dataset import require_lerobot
from cake_drake.learning.policies.mlp.acting import load as load_mlp
from cake_drake.learning.policies.mlp.features import EXTRA_INPUTS, OBS_IMAGES, OBS_STATE
from cake_drake.policy.observations import GOAL_START
from cake_drake.processes import temporaries_in

#: Action size of each action space a checkpoint can answer in (a chunk is not learned).
ACTION_SIZE = {"joint_position": 8, "ee_delta": 7}


def model_folder(path: Path) -> Path:
    """The folder with the policy's ``config.json`` and weights: ``path`` itself, or the
    last checkpoint of a training folder (``checkpoints/last/pretrained_model``)."""
    path = Path(path)
    folder = artifacts.lerobot_folder(path)
    if folder is not None:
        return folder
    if not path.exists():
        raise InputError(f"{path}: no such checkpoint folder")
    raise InputError(
        f"{path}: not a LeRobot checkpoint (no config.json and model.safetensors here, nor "
        "in checkpoints/last/pretrained_model); give a folder written by cake_drake.train"
    )


def _feature_shapes(path: Path, config: dict, key: str) -> dict[str, tuple[int, ...]]:
    features = config.get(key)
    if not isinstance(features, dict):
        raise InputError(f"{path}: field {key!r} is missing or not a mapping of features")
    out = {}
    for name, feature in features.items():
        shape = feature.get("shape") if isinstance(feature, dict) else None
        if not (
            isinstance(shape, list)
            and shape
            and all(isinstance(n, int) and not isinstance(n, bool) and n > 0 for n in shape)
        ):
            raise InputError(f"{path}: {key}.{name} has no shape (a list of positive "
                             f"integers), got {shape!r}")  # fmt: skip
        out[name] = tuple(shape)
    return out


def weight_shapes(path: Path) -> dict[str, tuple[int, ...]]:
    """The tensors of a ``model.safetensors`` and their shapes, from its header alone (no
    torch, nothing else read); one line for a file that is truncated or not one."""
    try:
        with open(path, "rb") as f:
            head = f.read(8)
            size = struct.unpack("<Q", head)[0] if len(head) == 8 else -1
            if not 2 <= size <= min(100 * 2**20, path.stat().st_size - 8):
                raise ValueError("its header's length does not fit the file (truncated?)")
            header = json.loads(f.read(size))
        total = path.stat().st_size - 8 - size
        out, end = {}, 0
        for name, tensor in header.items():
            if name == "__metadata__":
                continue
            out[name] = tuple(int(n) for n in tensor["shape"])
            end = max(end, int(tensor["data_offsets"][1]))
        if end > total:
            raise ValueError(f"its tensors need {end} bytes, the file holds {total} (truncated)")
    except (OSError, ValueError, KeyError, TypeError, struct.error) as e:
        raise InputError(f"{path}: not a readable safetensors file ({e})") from None
    return out


def read_checkpoint(folder: Path) -> dict:
    """The one checked reader of a checkpoint's ``config.json`` (whole-task policy or
    skill): a mapping with a ``type``, features with shapes, and, for the project's own
    ``cake_mlp``, weights whose shapes (read from ``model.safetensors``'s header) are the
    ones the config says: the inputs' statistics, the first layer's width (the inputs
    times ``n_obs_steps``, for a policy over numbers), the last layer's (``chunk_size``
    actions). One line naming the file and the field otherwise, before anything is built."""
    folder = Path(folder)
    path = folder / "config.json"
    config = read_json_mapping(path, "a LeRobot policy's config")
    if not isinstance(config.get("type"), str):
        raise InputError(f"{path}: field 'type' (the policy's kind) is missing")
    inputs = _feature_shapes(path, config, "input_features")
    outputs = _feature_shapes(path, config, "output_features")
    if "action" not in outputs:
        raise InputError(f"{path}: names no action feature (output_features.action)")
    weights = weight_shapes(folder / "model.safetensors")
    if config["type"] != "cake_mlp":
        return config
    ints = {}
    for key, default in (("n_obs_steps", 1), ("chunk_size", 10), ("n_action_steps", 5)):
        value = config.get(key, default)
        if not isinstance(value, int) or isinstance(value, bool) or value < 1:
            raise InputError(f"{path}: field {key!r} is {value!r}; a positive integer")
        ints[key] = value
    if ints["n_action_steps"] > ints["chunk_size"]:
        raise InputError(f"{path}: n_action_steps {ints['n_action_steps']} is more than "
                         f"chunk_size {ints['chunk_size']}")  # fmt: skip
    action = outputs["action"][0]
    names = {OBS_STATE: "state", **EXTRA_INPUTS}
    need = {"action_mean": (action,), "action_std": (action,)}
    for key, size in inputs.items():
        if key in names:
            need[f"{names[key]}_mean"] = need[f"{names[key]}_std"] = (size[0],)
    layers = sorted(int(k.split(".")[1]) for k in weights
                    if k.startswith("net.") and k.endswith(".weight"))  # fmt: skip
    if not layers:
        raise InputError(f"{folder / 'model.safetensors'}: holds no network (net.*.weight)")
    last = weights[f"net.{layers[-1]}.weight"]
    need[f"net.{layers[-1]}.weight"] = (ints["chunk_size"] * action, last[1])
    if not any(k.startswith(OBS_IMAGES) for k in inputs):  # numbers only: the first layer
        width = ints["n_obs_steps"] * sum(s[0] for k, s in inputs.items() if k in names)
        need[f"net.{layers[0]}.weight"] = (weights[f"net.{layers[0]}.weight"][0], width)
    for name, shape in need.items():
        if weights.get(name) != shape:
            said = "is missing" if name not in weights else f"has shape {list(weights[name])}"
            raise InputError(
                f"{folder / 'model.safetensors'}: tensor {name} {said}, but {path.name} "
                f"(its features, n_obs_steps {ints['n_obs_steps']}, chunk_size "
                f"{ints['chunk_size']}) needs {list(shape)}"
            )
    return config


def is_skill(config: dict) -> bool:
    """Whether a checkpoint's config is a learned skill's (it reads ``observation.skill``:
    the ground action it executes) rather than a whole-task policy's."""
    return "observation.skill" in (config.get("input_features") or {})


def action_size(folder: Path) -> int:
    """The size of the action the checkpoint in ``folder`` predicts."""
    config = read_checkpoint(folder)
    try:
        return int(config["output_features"]["action"]["shape"][0])
    except (KeyError, IndexError, TypeError, ValueError):
        raise InputError(
            f"{folder / 'config.json'}: names no action feature (output_features.action)"
        ) from None


def check_device(device: str) -> None:
    """Refuse (one line, exit 2) a device that is none, or ``cuda`` where torch sees no
    GPU; ``auto`` and ``cpu`` are checked without importing torch."""
    if device not in ("auto", "cpu", "cuda"):
        raise InputError(f"device {device!r}; choose one of: auto, cpu, cuda")
    if device == "cuda":
        device_for(device)


def device_for(device: str) -> str:
    """``auto`` is a CUDA GPU where torch sees one, else the CPU; ``cuda`` without one is
    refused (one line, exit 2)."""
    if device not in ("auto", "cpu", "cuda"):
        raise InputError(f"device {device!r}; choose one of: auto, cpu, cuda")
    if device == "cpu":
        return "cpu"
    import torch  # seconds, the lerobot extra: only to ask whether a GPU is here

    if torch.cuda.is_available():
        return "cuda"
    if device == "cuda":
        raise InputError("device cuda: torch sees no CUDA GPU here; use --device cpu (or auto)")
    return "cpu"


def camera_features(config: dict) -> dict[str, tuple[int, ...]]:
    """The cameras a checkpoint's policy reads: name -> (channels, height, width)."""
    prefix = "observation.images."
    return {
        key[len(prefix) :]: tuple(int(n) for n in feature.get("shape", ()))
        for key, feature in (config.get("input_features") or {}).items()
        if key.startswith(prefix)
    }


def check_cameras(path: Path, config: dict, cameras) -> None:
    """Refuse a checkpoint that reads cameras the run does not have, or has at other
    sizes: ``cameras`` are the run's (``name``, ``width``, ``height``)."""
    have = {c.name: (3, c.height, c.width) for c in cameras}
    for name, shape in camera_features(config).items():
        if name not in have:
            raise InputError(
                f"{path}: the policy sees camera {name!r}, which the scenario lacks "
                f"(cameras: {', '.join(have) or 'none'}); give it the cameras it was trained on"
            )
        if tuple(shape) != have[name]:
            raise InputError(
                f"{path}: the policy saw camera {name!r} at {shape[2]} x {shape[1]}; the "
                f"scenario's is {have[name][2]} x {have[name][1]}: give it the trained size"
            )


def describe(path: str | Path) -> str:
    """What learned the whole-task policy at ``path``, as a run's ``layers`` says it."""
    return f"imitation, {read_checkpoint(model_folder(Path(path))).get('type')}"


def check_folder(path: Path, action_space: str, device: str = "auto", cameras=None) -> Path:
    """Refuse, before anything is built, a folder that is no checkpoint, one whose action
    does not fit ``action_space``, one that sees cameras the run lacks (``cameras``: the
    run's, when given), or a device that is not here, or a Python or LeRobot that cannot
    load it; the model's folder. (An RL training's folder is checked by
    :func:`cake_drake.learning.policies.rl.check_folder`.)"""
    require_lerobot()
    folder = model_folder(path)
    if cameras is not None:
        check_cameras(path, read_checkpoint(folder), cameras)
    if is_skill(read_checkpoint(folder)):
        raise InputError(
            f"{path}: a learned skill (it reads observation.skill, the ground action it "
            "executes), not a whole-task policy; run it under the planner with motion.skills"
        )
    size = action_size(folder)
    want = ACTION_SIZE.get(action_space)
    if want is None:
        raise InputError(
            f"{path}: a checkpoint answers in {' or '.join(ACTION_SIZE)}, not {action_space}"
        )
    if size != want:
        fits = [k for k, v in ACTION_SIZE.items() if v == size]
        raise InputError(
            f"{path}: the checkpoint predicts {size} numbers an action; {action_space} takes "
            f"{want}" + (f" (it was trained in {fits[0]})" if fits else "")
        )
    check_device(device)
    return folder


@contextlib.contextmanager
def lerobot_temporaries():
    """While inside, Python's temporary files go in a folder of this process's own,
    removed after. LeRobot's config reader (``PreTrainedConfig.from_pretrained``) writes
    the config to a temporary file it never removes: one tmp*.json in the machine's
    temporary folder a load."""
    with tempfile.TemporaryDirectory(prefix="cake-drake-lerobot-") as tmp, temporaries_in(tmp):
        yield


class CheckpointPolicy:
    """See the module's docstring."""

    def __init__(self, path: str, device: str = "auto") -> None:
        require_lerobot()
        self.path = Path(path)
        self.folder = model_folder(self.path)
        check_device(device)
        self._device = device
        self._policy = None

    def _load(self) -> None:
        config = read_checkpoint(self.folder)
        numbers_only = config.get("type") == "cake_mlp" and not camera_features(config)
        # A perceptron over numbers acts on the CPU unless a GPU is asked for by name: at a
        # batch of one a GPU gains nothing, and finding one means importing torch.
        self.device = "cpu" if numbers_only and self._device == "auto" else device_for(self._device)
        if config.get("type") == "cake_mlp":
            # The project's own MLP acts without LeRobot: its LeRobot processors are the
            # identity (it standardises itself), and LeRobot's policy factory would import
            # every policy type (torchvision, diffusers: seconds a process). Reading
            # numbers only on the CPU, it acts in NumPy: no torch in the process.
            self._policy = load_mlp(self.folder, self.device)
            self._pre = self._post = None
            self._inputs = dict(config["input_features"])
            return
        # torch and LeRobot (seconds, the lerobot extra) only for a policy of LeRobot's own.
        import torch  # noqa: F401 - lerobot's policies are torch modules
        from lerobot.configs.policies import PreTrainedConfig
        from lerobot.policies.factory import get_policy_class, make_pre_post_processors

        import cake_drake.learning.policies.mlp.configuration_mlp  # noqa: F401 - registers cake_mlp

        with lerobot_temporaries():
            config = PreTrainedConfig.from_pretrained(self.folder)
        config.device = self.device
        with contextlib.redirect_stdout(io.StringIO()):  # lerobot prints where it loads from
            policy = get_policy_class(config.type).from_pretrained(self.folder, config=config)
        policy.to(self.device).eval()
        self._pre, self._post = make_pre_post_processors(
            config,
            pretrained_path=str(self.folder),
            preprocessor_overrides={"device_processor": {"device": self.device}},
        )
        self._inputs = dict(config.input_features)
        self._policy = policy

    def reset(self, task, seed: int) -> None:
        space = getattr(task, "action_space", "joint_position")
        check_folder(self.path, space, self._device)
        if self._policy is None:
            self._load()
        self._policy.reset()  # a new episode: no actions left from the last one
        if self._pre is not None:
            self._pre.reset()
            self._post.reset()

    def batch(self, observation) -> dict[str, np.ndarray]:
        """The policy's inputs from a slot or Gym observation, batched (1, ...), float32."""

        def get(slot_key, env_key, part=None):
            if slot_key in observation:
                return np.asarray(observation[slot_key])
            value = observation[env_key] if part is None else observation[env_key][part]
            return np.asarray(value)

        batch = {}
        for key in self._inputs:
            if key == "observation.state":
                value = get(key, "state")[:8]
            elif key == "observation.environment_state":
                value = get(key, "environment_state")
            elif key == "observation.goal":  # the goal without the poses
                value = get("observation.environment_state", "environment_state")[GOAL_START:]
            elif key.startswith("observation.images."):
                name = key[len("observation.images.") :]
                image = get(key, "images", name)
                value = np.ascontiguousarray(image.transpose(2, 0, 1)).astype(np.float32) / 255.0
            else:
                raise InputError(f"{self.folder}: the policy reads {key}, which no observation has")
            batch[key] = np.asarray(value, np.float32)[None]
        return batch

    def act(self, observation) -> np.ndarray:
        if self._pre is None:  # cake_mlp: NumPy in, NumPy out
            return self._policy.select_action(self.batch(observation))[0].astype(np.float64)
        import torch  # a LeRobot policy's own type: torch is loaded already (_load)

        with torch.inference_mode():
            batch = {k: torch.as_tensor(v) for k, v in self.batch(observation).items()}
            action = self._post(self._policy.select_action(self._pre(batch)))
        return action.squeeze(0).cpu().numpy().astype(np.float64)
