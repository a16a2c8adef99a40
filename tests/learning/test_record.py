"""Demonstrations as LeRobot datasets (written and read by lerobot itself), their replay,
and policy evaluation."""

from __future__ import annotations

import csv
import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.helpers import ROOT

#: Three blocks, joint-position actions, two small cameras: short episodes for the tests.
SUITE = """small:
  task: {generate: {blocks: 3}}
  reference: !Policy
    factory: "examples.expert_policy:make"
    action_space: joint_position
    max_steps: 300
  cameras:
    - {name: scene, width: 96, height: 96}
    - name: wrist
      attached_to: panda_hand
      xyz: [0.09, 0.0, 0.02]
      target: [0.0, 0.0, 0.2]
      width: 64
      height: 64
      fov_y_deg: 70.0
"""


def cake(command: str, *args: str, cwd: Path, env_extra: dict | None = None):
    env = {**os.environ, "PYTHONPATH": str(ROOT), **(env_extra or {})}
    return subprocess.run(
        [sys.executable, "-m", f"cake_drake.{command}", *args],
        cwd=cwd, capture_output=True, text=True, timeout=900, env=env,
    )  # fmt: skip


def test_record_without_lerobot_is_refused_with_the_pip_line(tmp_path):
    hide = tmp_path / "hide" / "lerobot"
    hide.mkdir(parents=True)
    (hide / "__init__.py").write_text("raise ImportError('not installed here')\n")
    (tmp_path / "suite.yaml").write_text(SUITE)
    env = {"PYTHONPATH": os.pathsep.join([str(tmp_path / "hide"), str(ROOT)])}
    r = cake("record", "suite.yaml", "--name", "small", "--out", "ds", cwd=tmp_path,
             env_extra=env)  # fmt: skip
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and "pip install 'cake_drake[lerobot]'" in r.stderr
    assert not (tmp_path / "ds").exists()


needs_lerobot = pytest.mark.skipif(
    importlib.util.find_spec("lerobot") is None,
    reason="the lerobot extra (make test installs it): pip install -e '.[lerobot]'",
)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """Two episodes recorded on one worker, and the same seeds on two."""
    folder = tmp_path_factory.mktemp("record")
    (folder / "suite.yaml").write_text(SUITE)
    runs = {}
    for workers in ("1", "2"):
        r = cake("record", "suite.yaml", "--name", "small", "--out", f"ds{workers}",
                 "--episodes", "2", "--workers", workers, cwd=folder)  # fmt: skip
        assert r.returncode == 0, r.stderr
        runs[workers] = r
    return folder, runs


@needs_lerobot
@pytest.mark.slow
def test_a_recording_is_a_lerobot_dataset_lerobot_reads(recorded):
    from cake_drake.learning.data.dataset import read

    folder, runs = recorded
    assert "2/2 episodes recorded" in runs["1"].stdout, runs["1"].stdout
    report = json.loads((folder / "ds1" / "report.json").read_text())
    data = read(folder / "ds1")
    info = json.loads((folder / "ds1" / "meta" / "info.json").read_text())
    assert info["codebase_version"] == "v3.0" and info["fps"] == 10
    assert data.meta.total_episodes == 2 and data.num_frames == report["frames"] == len(data)
    feats = data.meta.features
    assert feats["observation.state"]["dtype"] == "float32"
    assert tuple(feats["observation.state"]["shape"]) == (8,)
    assert tuple(feats["action"]["shape"]) == (8,)
    assert feats["observation.images.scene"]["dtype"] == "video"
    # Episode boundaries: each episode's frames are contiguous and counted from 0.
    table = data.hf_dataset.with_format("numpy")
    episodes = np.asarray(table["episode_index"])
    frames = np.asarray(table["frame_index"])
    for k in range(2):
        rows = np.flatnonzero(episodes == k)
        assert np.array_equal(rows, np.arange(rows[0], rows[0] + len(rows)))
        assert np.array_equal(frames[rows], np.arange(len(rows)))
    item = data[0]
    assert tuple(item["observation.images.scene"].shape) == (3, 96, 96)
    assert tuple(item["observation.images.wrist"].shape) == (3, 64, 64)
    assert item["task"] == report_task(folder, report["seeds"][0])


def report_task(folder: Path, seed: int) -> str:
    with np.load(folder / "ds1" / "episodes" / f"ep_{seed}.npz") as z:
        return str(z["task"])


@needs_lerobot
@pytest.mark.slow
def test_decoded_frames_match_the_rendered_ones_within_codec_tolerance(recorded):
    from cake_drake.learning.data.dataset import read

    folder, _ = recorded
    report = json.loads((folder / "ds1" / "report.json").read_text())
    data = read(folder / "ds1")
    with np.load(folder / "ds1" / "episodes" / f"ep_{report['seeds'][0]}.npz") as z:
        rendered = z["image_scene"]
        states = z["states"]
    for k in (0, len(rendered) // 2, len(rendered) - 1):
        decoded = data[k]["observation.images.scene"].numpy().transpose(1, 2, 0) * 255.0
        error = np.abs(decoded - rendered[k].astype(float))
        assert error.mean() < 6.0, (k, error.mean())  # H.264 at lerobot's quality, 8-bit
        assert np.allclose(data[k]["observation.state"].numpy(), states[k])


@needs_lerobot
@pytest.mark.slow
def test_the_same_seeds_give_the_same_parquet_bytes_on_one_worker_and_two(recorded):
    folder, _ = recorded
    one = sorted((folder / "ds1" / "data").rglob("*.parquet"))
    two = sorted((folder / "ds2" / "data").rglob("*.parquet"))
    assert [p.relative_to(folder / "ds1") for p in one] == [
        p.relative_to(folder / "ds2") for p in two
    ]
    assert all(a.read_bytes() == b.read_bytes() for a, b in zip(one, two, strict=True))


@needs_lerobot
@pytest.mark.slow
def test_skipping_lerobots_image_embedding_writes_the_same_parquet_bytes(recorded, tmp_path):
    """Our features hold no image (cameras are videos): the writer's shortcut past
    ``embed_images`` changes nothing LeRobot writes."""
    import pyarrow.parquet as pq
    from lerobot.datasets import dataset_writer
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from cake_drake.learning.data import dataset
    from cake_drake.learning.data.recording import load_episode

    folder, _ = recorded
    report = json.loads((folder / "ds1" / "report.json").read_text())
    rows = [json.loads((folder / "ds1" / "episodes" / f"ep_{s}.json").read_text())
            for s in report["seeds"]]  # fmt: skip

    def episodes():
        for row in rows:
            npz = folder / "ds1" / "episodes" / f"ep_{row['seed']}.npz"
            yield load_episode(npz, row, images=False)

    embedded = []
    real = dataset_writer.embed_images

    def counted(table):
        embedded.append(len(table))
        return real(table)

    dataset.write(tmp_path / "fast", episodes(), 10, "joint_position", ())
    dataset_writer.embed_images = counted
    try:
        with dataset._quiet():
            dataset._write(LeRobotDataset, tmp_path / "lerobot", episodes(), 10,
                           "joint_position", ())  # fmt: skip
    finally:
        dataset_writer.embed_images = real
    assert dataset_writer.embed_images is real and len(embedded) == len(rows)
    fast = sorted((tmp_path / "fast").rglob("*.parquet"))
    plain = sorted((tmp_path / "lerobot").rglob("*.parquet"))
    assert [p.relative_to(tmp_path / "fast") for p in fast] == [
        p.relative_to(tmp_path / "lerobot") for p in plain
    ]
    for a, b in zip(fast, plain, strict=True):
        ta, tb = pq.read_table(a), pq.read_table(b)
        assert ta.equals(tb), a
        # The schema's metadata too, but for the fingerprint of the skipped map: a cache
        # key of ``datasets``, which nothing reads back.
        meta = [json.loads((t.schema.metadata or {}).get(b"huggingface", b"{}")) for t in (ta, tb)]
        assert [{k: v for k, v in m.items() if k != "fingerprint"} for m in meta] == [
            {k: v for k, v in meta[1].items() if k != "fingerprint"}
        ] * 2, a


@needs_lerobot
@pytest.mark.slow
def test_on_local_ray_the_same_seeds_give_the_same_parquet_bytes(recorded):
    pytest.importorskip("ray")
    folder, _ = recorded
    r = cake("record", "suite.yaml", "--name", "small", "--out", "dsray", "--episodes", "2",
             "--ray", "--workers", "2", cwd=folder)  # fmt: skip
    assert r.returncode == 0, r.stderr
    one = sorted((folder / "ds1" / "data").rglob("*.parquet"))
    ray = sorted((folder / "dsray" / "data").rglob("*.parquet"))
    assert len(one) == len(ray) > 0
    assert all(a.read_bytes() == b.read_bytes() for a, b in zip(one, ray, strict=True))


@needs_lerobot
@pytest.mark.slow
def test_replaying_the_actions_open_loop_rebuilds_every_goal(recorded):
    folder, _ = recorded
    r = cake("record", "--replay", "ds1", "--workers", "2", cwd=folder)
    assert r.returncode == 0, r.stderr
    assert "2/2 episodes rebuild the goal" in r.stdout, r.stdout


@needs_lerobot
@pytest.mark.slow
def test_resume_records_only_the_rest_and_a_recording_is_not_reused_without_it(recorded):
    folder, _ = recorded
    r = cake("record", "suite.yaml", "--name", "small", "--out", "ds1", "--episodes", "3",
             cwd=folder)  # fmt: skip
    assert r.returncode == 2 and "--resume continues it" in r.stderr, r.stderr
    kept = {p.name: p.stat().st_mtime_ns for p in (folder / "ds1" / "episodes").glob("ep_*")}
    r = cake("record", "suite.yaml", "--name", "small", "--out", "ds1", "--episodes", "3",
             "--resume", cwd=folder)  # fmt: skip
    assert r.returncode == 0, r.stderr
    after = {p.name: p.stat().st_mtime_ns for p in (folder / "ds1" / "episodes").glob("ep_*")}
    assert all(after[n] == t for n, t in kept.items())  # the first two were not recorded again
    assert len(after) > len(kept)
    from cake_drake.learning.data.dataset import read

    assert read(folder / "ds1").meta.total_episodes == 3


@pytest.mark.slow
def test_evaluation_tells_the_expert_from_the_random_policy(tmp_path):
    from cake_drake.sweeps.table import read_table

    (tmp_path / "suite.yaml").write_text(SUITE.split("  cameras:")[0])
    results = {}
    for policy in ("examples.expert_policy:make", "examples.random_policy:make"):
        name = policy.split(".")[1].split(":")[0]
        frames = ["--frames", "2"] if name == "random_policy" else []
        r = cake("evaluate", policy, "--suite", "suite.yaml", "--name", "small", "--episodes",
                 "3", "--out", name, *frames, cwd=tmp_path)  # fmt: skip
        assert r.returncode == 0, r.stderr
        results[name] = json.loads((tmp_path / name / "summary.json").read_text())
        rows = list(csv.DictReader((tmp_path / name / "results.csv").open()))
        assert len(rows) == 3 and (tmp_path / name / "success.png").stat().st_size > 0
        table = read_table(tmp_path / name / "results.parquet")
        assert [r["seed"] for r in table] == [0, 1, 2] and set(table[0]) == set(rows[0])
    assert results["expert_policy"]["success"] == 3
    assert results["random_policy"]["success"] == 0
    lo, hi = results["random_policy"]["ci95"]
    assert lo == 0.0 and 0.4 < hi < 0.8  # Wilson's interval for 0/3
    # Where the failures stopped: the goal's facts missing at each end, counted, and the
    # first two failures' last pictures side by side.
    rows = list(csv.DictReader((tmp_path / "random_policy" / "results.csv").open()))
    assert all(r["missing"].startswith("(") for r in rows), rows
    counted = results["random_policy"]["missing_at_end"]
    assert sum(counted.values()) == sum(r["missing"].count("(") for r in rows) > 0
    assert results["expert_policy"]["missing_at_end"] == {}
    assert not (tmp_path / "expert_policy" / "failures.png").exists()
    from PIL import Image

    with Image.open(tmp_path / "random_policy" / "failures.png") as picture:
        assert picture.size[0] > 1.5 * picture.size[1]  # two pictures in a row
    r = cake("evaluate", "examples.random_policy:make", "--suite", "suite.yaml", "--name",
             "small", "--frames", "65", "--out", "refused", cwd=tmp_path)  # fmt: skip
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "--frames 65" in r.stderr
    assert not (tmp_path / "refused").exists()


def _damaged_copy(source: Path, dest: Path, damage: str) -> Path:
    import shutil

    shutil.copytree(source, dest)
    info_path = dest / "meta" / "info.json"
    info = json.loads(info_path.read_text())
    if damage == "truncated video":
        video = sorted((dest / "videos").glob("**/*.mp4"))[0]
        video.write_bytes(video.read_bytes()[: video.stat().st_size // 2])
    elif damage == "truncated data":
        data = sorted((dest / "data").glob("**/*.parquet"))[0]
        data.write_bytes(data.read_bytes()[: data.stat().st_size // 2])
    elif damage == "action shape":
        info["features"]["action"]["shape"] = [9]
        info["features"]["action"]["names"] = None
    elif damage == "fps 0":
        info["fps"] = 0
    elif damage == "report not a mapping":
        (dest / "report.json").write_text("[1, 2, 3]")
    elif damage == "recipe field of another type":
        report = json.loads((dest / "report.json").read_text())
        report["training"] = {"steps": "many"}
        (dest / "report.json").write_text(json.dumps(report))
    elif damage == "metadata deleted":
        (dest / "meta" / "stats.json").unlink()
    info_path.write_text(json.dumps(info))
    return dest


@needs_lerobot
@pytest.mark.parametrize(
    "damage, words",
    [
        ("truncated video", ".mp4: unreadable video"),
        ("truncated data", ".parquet: unreadable table"),
        ("action shape", "features.action has shape [9], but file-000.parquet's actions hold 8"),
        ("fps 0", "info.json: field 'fps' is 0"),
        ("report not a mapping", "report.json: holds a list, not a mapping"),
        ("recipe field of another type", "report.json: training.steps is 'many'; a recipe's "
                                          "steps is int"),
        ("metadata deleted", "meta/stats.json: missing from the dataset; a LeRobot dataset is "
                             "read from its own folder, never fetched"),
    ],
)  # fmt: skip
def test_a_damaged_recording_is_one_line_and_never_a_download(recorded, tmp_path, damage, words):
    folder, _ = recorded
    ds = _damaged_copy(folder / "ds1", tmp_path / "ds", damage)
    # Whatever the user's environment says, nothing is fetched: every attempt to reach
    # another machine is watched (and stopped) in the process itself.
    env = {"HF_HUB_OFFLINE": "0", "HF_DATASETS_OFFLINE": "0", **_watched(tmp_path)}
    r = cake("train", str(ds), "--out", "run", "--steps", "2", "--batch-size", "2",
             "--device", "cpu", cwd=tmp_path, env_extra=env)  # fmt: skip
    assert r.returncode == 2, r.stderr[-2000:]
    assert r.stderr.count("\n") == 1 and words in r.stderr, r.stderr[-2000:]
    assert not (tmp_path / "run").exists()
    assert _attempts(tmp_path) == [], "a damaged recording reached for the network"


#: A sitecustomize that records (and refuses) every look-up of another machine's name and
#: every connection to another machine, through Python's audit hooks.
_WATCH = """
import os, sys

_LOG = os.environ["CAKE_DRAKE_NET_LOG"]
_HERE = ("localhost", "127.0.0.1", "::1", "", None)


def _hook(event, args):
    if event == "socket.getaddrinfo":
        host = args[0].decode() if isinstance(args[0], bytes) else args[0]
    elif event == "socket.connect" and isinstance(args[1], tuple):
        host = args[1][0]
    else:
        return
    if host in _HERE or str(host).startswith("127."):
        return
    with open(_LOG, "a") as f:
        f.write(f"{event} {host}\\n")
    raise OSError(f"network use watched by the test: {event} {host}")


sys.addaudithook(_hook)
"""


def _watched(tmp_path: Path) -> dict:
    site = tmp_path / "watch"
    site.mkdir(exist_ok=True)
    (site / "sitecustomize.py").write_text(_WATCH)
    log = tmp_path / "net.log"
    log.write_text("")
    return {"PYTHONPATH": f"{site}{os.pathsep}{ROOT}", "CAKE_DRAKE_NET_LOG": str(log)}


def _attempts(tmp_path: Path) -> list[str]:
    return (tmp_path / "net.log").read_text().splitlines()


def test_the_network_watch_sees_an_attempt(tmp_path):
    # The watch's own oracle: a process that reaches for a hub is seen.
    env = {**os.environ, **_watched(tmp_path)}
    code = "import urllib.request; urllib.request.urlopen('https://huggingface.co', timeout=5)"
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                       timeout=60)  # fmt: skip
    assert r.returncode != 0
    assert _attempts(tmp_path) == ["socket.getaddrinfo huggingface.co"]


@needs_lerobot
def test_a_recording_rewritten_in_place_with_its_old_times_is_read_anew(recorded, tmp_path):
    """The Arrow copy the datasets library caches is keyed on the tables' content, not on
    their paths and times: a table replaced by another, its time kept (cp -p, an archive),
    is read as it is now."""
    import shutil

    from cake_drake.learning.data.dataset import content_digest, read

    folder, _ = recorded
    ds = tmp_path / "ds"
    shutil.copytree(folder / "ds1", ds)
    first = read(ds)
    before = np.asarray(first.hf_dataset.with_format("numpy")["action"])
    table = sorted((ds / "data").glob("**/*.parquet"))[0]
    stat = table.stat()
    digest = content_digest(ds)
    import pyarrow as pa
    import pyarrow.parquet as pq

    data = pq.read_table(table)
    doubled = pa.array([[2.0 * x for x in row] for row in data["action"].to_pylist()],
                       type=data.schema.field("action").type)  # fmt: skip
    pq.write_table(data.set_column(data.schema.get_field_index("action"), "action", doubled),
                   table)  # fmt: skip
    os.utime(table, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    assert table.stat().st_mtime_ns == stat.st_mtime_ns and content_digest(ds) != digest
    after = np.asarray(read(ds).hf_dataset.with_format("numpy")["action"])
    np.testing.assert_allclose(after, 2 * before, rtol=1e-6)


def test_a_learning_task_generates_what_its_scenario_says_or_refuses_it():
    """``task.generate.tall`` reaches the episodes (few, tall towers); a generate field the
    episodes cannot follow is one line, not silently dropped."""
    from cake_drake.errors import InputError
    from cake_drake.learning.data.recording import spec_from_scenario
    from cake_drake.pipeline import check
    from cake_drake.scenario import Generate, Policy, Scenario
    from cake_drake.symbolic.roles import blocksworld_view

    def tallest(problem) -> int:
        view = blocksworld_view(problem)
        below = {f[1]: f[2] for f in view.init if f[0] == "on"}

        def height(b: str) -> int:
            return 1 + (height(below[b]) if b in below else 0)

        return max(height(b) for b in view.blocks)

    s = Scenario(reference=Policy(factory="cake_drake.learning.expert:make"))
    heights = {}
    for tall in (False, True):
        s.task.generate = Generate(blocks=8, tall=tall)
        spec = spec_from_scenario(s)
        assert spec.tall is tall
        env = spec.env()
        heights[tall] = [tallest(check(env.episode_scenario(seed), write=False).problem)
                         for seed in range(6)]  # fmt: skip
    assert min(heights[True]) >= 3 and sum(heights[True]) > sum(heights[False]), heights
    s.task.generate = Generate(blocks=5, partial=True)
    with pytest.raises(InputError, match="task.generate.partial: a learning task's episodes"):
        spec_from_scenario(s)
