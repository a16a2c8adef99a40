"""Headless pictures of the world: Drake's ``RgbdSensor`` on ``RenderEngineVtk``.

VTK renders through EGL on Mesa's software rasteriser, so no display and no GPU are
needed (Debian packages: libegl1 libegl-mesa0 libgl1-mesa-dri libgbm1). The renderer
lives in its own small diagram, built from a world state, so the simulation diagram
carries no camera and a picture can be taken of any state.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from pydrake.geometry import (
    ClippingRange,
    ColorRenderCamera,
    DepthRange,
    DepthRenderCamera,
    RenderCameraCore,
)
from pydrake.math import RigidTransform
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.sensors import CameraInfo, RgbdSensor

from cake_drake.errors import InputError
from cake_drake.world.cameras import look_at, render_engine
from cake_drake.world.scene import Q_HOME, WorldConfig, add_world, set_arm_positions, set_cube_poses

RENDERER = "vtk"
#: Default viewpoint: in front of and to the right of the robot, looking at the slots.
EYE = (1.45, -1.0, 0.95)
TARGET = (0.3, 0.0, 0.28)


class Renderer:
    """A world for pictures only: build once (meshes load here), then :meth:`render` states."""

    def __init__(
        self,
        blocks: Sequence[str],
        width: int = 800,
        height: int = 600,
        eye: Sequence[float] = EYE,
        target: Sequence[float] = TARGET,
    ) -> None:
        builder = DiagramBuilder()
        self.scene = add_world(builder, blocks, WorldConfig(time_step=0.0))
        sg = self.scene.scene_graph
        sg.AddRenderer(RENDERER, render_engine())
        core = RenderCameraCore(
            RENDERER,
            CameraInfo(width, height, np.radians(45.0)),
            ClippingRange(0.05, 5.0),
            RigidTransform(),
        )
        # Only the colour image is ever evaluated; the depth camera is required by the API.
        self._sensor = builder.AddSystem(
            RgbdSensor(
                sg.world_frame_id(),
                look_at(eye, target),
                ColorRenderCamera(core, False),
                DepthRenderCamera(core, DepthRange(0.06, 4.9)),
            )
        )
        builder.Connect(sg.get_query_output_port(), self._sensor.query_object_input_port())
        self._diagram = builder.Build()
        self._context = self._diagram.CreateDefaultContext()
        self._plant_context = self.scene.plant.GetMyMutableContextFromRoot(self._context)

    def render(
        self,
        cube_poses: Mapping[str, RigidTransform],
        q_arm: Sequence[float] = Q_HOME,
        fingers: float = 0.04,
    ) -> np.ndarray:
        """RGBA image (height x width x 4, uint8) of the world in the given state."""
        set_arm_positions(self.scene, self._plant_context, q_arm, fingers)
        set_cube_poses(self.scene, self._plant_context, cube_poses)
        sensor_context = self._sensor.GetMyContextFromRoot(self._context)
        image = self._sensor.color_image_output_port().Eval(sensor_context)
        return np.array(image.data, copy=True)


def png_bytes(rgba: np.ndarray) -> bytes:
    """An RGBA array (height x width x 4, uint8) as a PNG file (the standard library's
    zlib; every row with the "Sub" filter, which suits large flat colours)."""
    import struct
    import zlib

    rgba = np.ascontiguousarray(rgba, dtype=np.uint8)
    height, width, channels = rgba.shape
    if channels != 4:
        raise ValueError(f"expected an RGBA image, got {channels} channels")
    sub = rgba.reshape(height, width * 4).copy()
    sub[:, 4:] -= rgba.reshape(height, width * 4)[:, :-4]  # wraps modulo 256, as PNG's Sub
    rows = np.hstack([np.ones((height, 1), np.uint8), sub])  # filter type 1 (Sub)

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
        )

    header = struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0)  # 8-bit RGBA
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(rows.tobytes(), 6))
        + chunk(b"IEND", b"")
    )


def save_png(rgba: np.ndarray, path: str | Path) -> None:
    """Write an RGBA array as PNG (written whole: to a temporary name, then renamed)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".part")
    try:
        tmp.write_bytes(png_bytes(rgba))
        tmp.replace(path)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise InputError(f"{path}: cannot write the picture ({e.strerror})") from None
