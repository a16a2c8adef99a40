"""replay.html in a real browser: headless Chromium opens a short run's page and we look.

The browser test runs a two-cube run with Meshcat, lets Chromium load ``replay.html`` and
play the recording to its end (virtual time, software GL), takes a screenshot and checks
the pixels: the page is not blank, both cubes' colours show, and the robot's silhouette is
one piece from its base to its hand. The last check is the one that caught the detached
arm: the hand and links 5-6 were never drawn, so the base's piece stopped at the elbow.

``CAKE_DRAKE_REPLAY=/path/to/replay.html`` points the browser check at another recording of
the same two-cube run (same deterministic run, so the same final pose), e.g. one made
before a fix, to see that the check fails on it.
"""

from __future__ import annotations

import base64
import colorsys
import gzip
import os
import shutil
import signal
import subprocess
from collections import deque
from pathlib import Path

import numpy as np
import pytest

from cake_drake.outputs.replay import (
    CAMERA_POSITION,
    CAMERA_TARGET,
    compress_static_html,
)
from tests.helpers import ROOT

CHROMIUM = "chromium"
WIDTH, HEIGHT = 1200, 800
#: Meshcat's default vertical field of view (three.js PerspectiveCamera), degrees.
FOV_DEG = 75.0
#: How near (pixels) the robot's piece must come to the hand's projected position.
REACH_PX = 25

TWO_CUBES = """(define (problem two-cubes) (:domain blocksworld)
  (:objects a b)
  (:init (on-table a) (on-table b) (clear a) (clear b) (arm-empty))
  (:goal (on a b)))
"""
#: Diffuse colours of the first two cube models (models/cubes/cube_a.sdf, cube_b.sdf).
CUBE_RGB = {"a": (0.85, 0.12, 0.12), "b": (0.95, 0.55, 0.05)}


# --- the page's data --------------------------------------------------------------------


def _static_page(commands: list[bytes]) -> str:
    fetches = "\n".join(
        f'fetch("data:application/octet-binary;base64,{base64.b64encode(c).decode()}")\n'
        "    .then(res => res.arrayBuffer())\n"
        "    .then(buffer => viewer.handle_command_bytearray(new Uint8Array(buffer)));"
        for c in commands
    )
    return f"<script>\nvar viewer = 1;\n{fetches}\n</script>"


def test_compressed_page_keeps_every_command_in_order():
    commands = [b"first" * 50, b"\x00\x01second", b"third" * 300]
    page = compress_static_html(_static_page(commands))
    assert "octet-binary" not in page and page.count("DecompressionStream") == 1
    packed = page.split("const commands = [", 1)[1].split("]", 1)[0]
    unpacked = [gzip.decompress(base64.b64decode(p.strip(' "'))) for p in packed.split(",")]
    assert unpacked == commands
    assert page.startswith("<script>\nvar viewer = 1;\n") and page.endswith("</script>")


def test_unknown_page_is_left_alone():
    assert compress_static_html("<html>no commands</html>") == "<html>no commands</html>"


def test_drakes_page_is_recognised():
    """If Drake changes how its static page loads the scene, say so here (not by size)."""
    from pydrake.geometry import Meshcat

    meshcat = Meshcat()
    meshcat.SetProperty("/Grid", "visible", False)
    html = meshcat.StaticHtml()
    assert compress_static_html(html) != html


# --- the browser ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def two_cube_run(tmp_path_factory):
    """A short run (pick up a, stack it on b) with Meshcat, outputs written."""
    from pydrake.geometry import StartMeshcat

    from cake_drake.pipeline import run
    from cake_drake.scenario import Scenario

    folder = tmp_path_factory.mktemp("replay")
    problem = folder / "two_cubes.pddl"
    problem.write_text(TWO_CUBES)
    s = Scenario()
    s.task.problem = str(problem)
    s.outputs.folder, s.outputs.render = str(folder / "out"), False
    result = run(s, meshcat=StartMeshcat())
    assert result.success, result.message
    return folder / "out", result


def screenshot(page: Path, png: Path, budget_ms: int = 20000, attempts: int = 2) -> np.ndarray:
    """Open ``page`` in headless Chromium, let it play for ``budget_ms``; RGB in 0..1.

    Headless Chromium with a virtual-time budget now and then never takes its screenshot
    (seen about once in ten runs here, on large pages): such a run is killed, whole process
    group, after a minute and tried again.
    """
    import matplotlib.image

    exe = shutil.which(CHROMIUM)
    assert exe, f"{CHROMIUM} not on PATH: `make test` installs it (system-packages.txt)"
    cmd = [
        exe,
        "--headless=new",
        "--no-sandbox",
        "--use-gl=swiftshader",
        "--enable-unsafe-swiftshader",
        f"--window-size={WIDTH},{HEIGHT}",
        f"--virtual-time-budget={budget_ms}",
        f"--screenshot={png}",
        page.resolve().as_uri(),
    ]
    for _ in range(attempts):
        proc = subprocess.Popen(
            cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
        )
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            continue
        assert proc.returncode == 0, f"{CHROMIUM} exited with {proc.returncode}"
        return matplotlib.image.imread(png)[..., :3]
    pytest.fail(f"{CHROMIUM} took no screenshot of {page} in {attempts} tries of 60 s")


def project(p_W) -> tuple[float, float]:
    """Pixel (column, row) of the world point ``p_W`` through the replay's camera."""
    eye, target = np.array(CAMERA_POSITION), np.array(CAMERA_TARGET)
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    d = np.asarray(p_W, float) - eye
    t = np.tan(np.radians(FOV_DEG) / 2)
    x = d @ right / (d @ forward * t * WIDTH / HEIGHT)
    y = d @ up / (d @ forward * t)
    return (x + 1) / 2 * WIDTH, (1 - y) / 2 * HEIGHT


def robot_mask(rgb: np.ndarray) -> np.ndarray:
    """Pixels of the robot: white and black parts are grey; sky, table and cubes are not."""
    grey = rgb.max(axis=2) - rgb.min(axis=2) < 0.07
    grey[:30, :] = False  # Meshcat's "Open Controls" bar
    return grey


def piece_from(mask: np.ndarray, seed: tuple[int, int]) -> np.ndarray:
    """The 8-connected piece of ``mask`` that contains ``seed`` (row, col)."""
    piece = np.zeros_like(mask)
    piece[seed] = True
    todo = deque([seed])
    rows, cols = mask.shape
    while todo:
        r, c = todo.popleft()
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                rr, cc = r + dr, c + dc
                if 0 <= rr < rows and 0 <= cc < cols and mask[rr, cc] and not piece[rr, cc]:
                    piece[rr, cc] = True
                    todo.append((rr, cc))
    return piece


def nearest(mask: np.ndarray, col: float, row: float) -> tuple[tuple[int, int], float]:
    rows, cols = np.nonzero(mask)
    d = np.hypot(rows - row, cols - col)
    k = int(np.argmin(d))
    return (int(rows[k]), int(cols[k])), float(d[k])


def colour_pixels(rgb: np.ndarray, target: tuple[float, float, float]) -> int:
    """Saturated pixels within 10 degrees of ``target``'s hue (shading changes value only)."""
    hue = colorsys.rgb_to_hsv(*target)[0]
    mx, mn = rgb.max(axis=2), rgb.min(axis=2)
    sat = np.where(mx > 0, (mx - mn) / np.maximum(mx, 1e-9), 0)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    delta = np.maximum(mx - mn, 1e-9)
    h = (
        np.where(
            mx == r,
            ((g - b) / delta) % 6,
            np.where(mx == g, (b - r) / delta + 2, (r - g) / delta + 4),
        )
        / 6
    )
    dh = np.minimum(abs(h - hue), 1 - abs(h - hue))
    return int(np.count_nonzero((sat > 0.5) & (mx > 0.2) & (dh < 10 / 360)))


def hand_and_base(result) -> tuple[np.ndarray, np.ndarray]:
    """World positions of the middle of the hand at the end, and of the robot's base."""
    plant = result.cake.scene.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, result.cake.scene.arm, result.execution.q_final)
    hand = plant.GetBodyByName("panda_hand", result.cake.scene.hand)
    X_WH = plant.EvalBodyPoseInWorld(context, hand)
    return X_WH.multiply([0.0, 0.0, 0.04]), np.array([0.0, 0.0, 0.15])


@pytest.mark.slow
def test_replay_shows_whole_robot_in_a_browser(two_cube_run, tmp_path):
    out, result = two_cube_run
    page = Path(os.environ.get("CAKE_DRAKE_REPLAY", out / "replay.html"))
    rgb = screenshot(page, tmp_path / "replay.png")
    assert rgb.shape == (HEIGHT, WIDTH, 3)

    # Not blank: a rendered scene, not one flat colour.
    assert rgb.std() > 0.05, "the page rendered (almost) one colour: no scene"

    # The cubes, in their colours.
    for block, colour in CUBE_RGB.items():
        n = colour_pixels(rgb, colour)
        assert n > 40, f"cube {block}'s colour shows on {n} pixels only"

    # The robot: one piece from its base to its hand.
    mask = robot_mask(rgb)
    assert 0.005 < mask.mean() < 0.3, f"robot-grey covers {mask.mean():.1%} of the page"
    p_hand, p_base = hand_and_base(result)
    (base_seed, base_gap) = nearest(mask, *project(p_base))
    assert base_gap < REACH_PX, f"nothing robot-grey within {REACH_PX} px of the base"
    piece = piece_from(mask, base_seed)
    _, gap = nearest(piece, *project(p_hand))
    assert gap < REACH_PX, (
        f"the robot's silhouette from its base stops {gap:.0f} px short of its hand: "
        "the arm is drawn apart from its hand"
    )


@pytest.mark.alone
@pytest.mark.slow
def test_meshcat_from_a_terminal_runs_in_real_time_and_waits_for_enter(tmp_path):
    """From a terminal, --meshcat holds the simulation to real time and keeps the viewer
    (its server is this process) until Enter; with stdin not a terminal (CI) it does not."""
    import os
    import pty
    import subprocess
    import sys

    master, slave = pty.openpty()
    proc = subprocess.Popen(
        [sys.executable, "-m", "cake_drake.run", "--meshcat", "--no-render", "--quiet",
         "--out", "o"],
        cwd=tmp_path, stdin=slave, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip
    os.close(slave)
    seen = ""
    while "press Enter" not in seen:
        line = proc.stderr.readline()
        assert line, f"ended without the prompt: {seen}"
        seen += line
    assert proc.poll() is None  # waiting for the user
    os.write(master, b"\n")
    out, _ = proc.communicate(timeout=60)
    os.close(master)
    assert proc.returncode == 0 and "goal reached" in out
    assert "realtime_rate: 1.0" in (tmp_path / "o" / "scenario.yaml").read_text()
