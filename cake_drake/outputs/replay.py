"""Watching a run in Meshcat: the live view, and ``replay.html``, its recording.

One place decides what a viewer sees, for the live page and the saved file alike:

* what is drawn: the illustration geometry only, i.e. the table, the robot and the cubes as
  they look. Collision shapes, inertia ellipsoids and contact forces stay out (they were
  most of the old 39 MB file and hidden anyway);
* how often: :data:`DISPLAY_RATE_HZ` frames per simulated second, for the live view and
  for the recording, instead of every 10 ms simulation step;
* from where: a camera that frames the table, the robot and the cubes' slots, on a plain
  sky-coloured backdrop without the floor grid (the table is the floor; the grid lay in its
  top surface and flickered through it).

``replay.html`` is Meshcat's own self-contained page (no network): it plays the run once
when opened and stops on the last frame; *Open Controls -> Animations* has play, pause,
reset and a time slider.
"""

from __future__ import annotations

import base64
import gzip
import re
from pathlib import Path

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams, Role, SceneGraph
from pydrake.systems.framework import DiagramBuilder

#: Frames per simulated second drawn live and kept in the recording. Smooth to the eye;
#: a 10 ms simulation step would be 100.
DISPLAY_RATE_HZ = 30.0
#: The camera: where it stands and the point it looks at (world frame, m). It sees the
#: 1.2 m table, the robot at its back edge and the arc of slots in front of it.
CAMERA_POSITION = (1.25, -0.9, 0.75)
CAMERA_TARGET = (0.3, 0.0, 0.1)
#: The backdrop: Meshcat's background gradient, top and bottom (RGB in 0..1). Blue, so
#: that the white robot, the wooden table and the coloured cubes all stand out.
SKY_TOP = (0.62, 0.74, 0.88)
SKY_BOTTOM = (0.36, 0.47, 0.62)
#: Where the visualizer draws, in Meshcat's scene tree.
PREFIX = "illustration"


def add_visualization(
    builder: DiagramBuilder, scene_graph: SceneGraph, meshcat: Meshcat
) -> MeshcatVisualizer:
    """Draw ``scene_graph``'s illustration geometry in ``meshcat`` at the display rate.

    Also sets the view (:func:`frame_camera`), so the live page and the replay open alike.
    """
    params = MeshcatVisualizerParams()
    params.role = Role.kIllustration
    params.publish_period = 1.0 / DISPLAY_RATE_HZ
    params.prefix = PREFIX
    visualizer = MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat, params)
    frame_camera(meshcat)
    return visualizer


def frame_camera(meshcat: Meshcat) -> None:
    """Point the camera at the work area and set the plain backdrop (no grid, no axes)."""
    meshcat.SetCameraPose(np.array(CAMERA_POSITION), np.array(CAMERA_TARGET))
    meshcat.SetProperty("/Grid", "visible", False)
    meshcat.SetProperty("/Axes", "visible", False)
    meshcat.SetProperty("/Background", "top_color", list(SKY_TOP))
    meshcat.SetProperty("/Background", "bottom_color", list(SKY_BOTTOM))


def start_recording(meshcat: Meshcat) -> None:
    """Record what the visualizer draws from now on, at :data:`DISPLAY_RATE_HZ`.

    The live view keeps updating while it records.
    """
    meshcat.StartRecording(DISPLAY_RATE_HZ, True)


def write_replay(meshcat: Meshcat, path: Path) -> int:
    """Stop the recording and write it as a self-contained page to ``path``; its size, bytes.

    The page opens on the camera of :func:`frame_camera` and plays the recording once.
    Its scene data are gzip-compressed (:func:`compress_static_html`).
    """
    meshcat.StopRecording()
    meshcat.PublishRecording()
    data = compress_static_html(meshcat.StaticHtml()).encode()
    Path(path).write_bytes(data)
    return len(data)


#: How Meshcat's static page hands each scene command to the viewer: one ``fetch`` of a
#: base64 ``data:`` URL per command, all started at once.
_COMMAND = re.compile(
    r'fetch\("data:application/octet-binary;base64,(?P<data>[A-Za-z0-9+/=]*)"\)\s*'
    r"\.then\(res => res\.arrayBuffer\(\)\)\s*"
    r"\.then\(buffer => viewer\.handle_command_bytearray\(new Uint8Array\(buffer\)\)\);"
)
#: The same commands gzip-compressed, unpacked by the browser (``DecompressionStream``:
#: Chrome 80, Firefox 113, Safari 16.4) and applied one after another, in their order. A
#: command the viewer fails on is reported on the console and skipped, as before.
_LOADER = """(async () => {
      const commands = [%s];
      for (const data of commands) {
        try {
          const packed = await fetch("data:application/gzip;base64," + data);
          const stream = packed.body.pipeThrough(new DecompressionStream("gzip"));
          const buffer = await new Response(stream).arrayBuffer();
          viewer.handle_command_bytearray(new Uint8Array(buffer));
        } catch (error) {
          console.error("replay: a scene command failed:", error);
        }
      }
    })();"""


def compress_static_html(html: str) -> str:
    """Meshcat's static page with its scene commands gzip-compressed: about a third the size.

    The meshes (OBJ text) and the recording (msgpack) are most of the page and compress
    well. A page in a form this does not recognise is returned unchanged.
    """
    commands = list(_COMMAND.finditer(html))
    if not commands:
        return html
    packed = [
        base64.b64encode(gzip.compress(base64.b64decode(m["data"]), 9, mtime=0)).decode()
        for m in commands
    ]
    loader = _LOADER % ", ".join(f'"{p}"' for p in packed)
    first, last = commands[0], commands[-1]
    between = _COMMAND.sub("", html[first.start() : last.end()])
    return html[: first.start()] + loader + between + html[last.end() :]
