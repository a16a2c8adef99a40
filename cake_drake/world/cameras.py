"""Cameras in the simulated world: Drake ``RgbdSensor``s on the headless VTK renderer.

A scenario's ``cameras:`` list declares them; a run without cameras builds no renderer
and pays nothing. A camera is fixed in the world (``attached_to: world``) or rides on a
body of the robot (``attached_to: panda_hand``), at ``xyz`` in that frame, looking at
``target`` (in the same frame) or turned by ``rpy_deg``. Drake's camera frame looks
along +z, with +x to the right of the image and +y down.

Images are evaluated when asked for (a policy's step, a recording's frame): ``rate_hz``
is how often a policy or a recording samples the camera, not a rate the simulation
renders at. VTK renders through EGL on Mesa's software rasteriser: no display and no GPU
(Debian: libegl1 libegl-mesa0 libgl1-mesa-dri libgbm1); where NVIDIA's EGL is installed,
VTK picks it by itself, and :func:`renderer_in_use` says which one a process renders with.
"""

import ctypes
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from pydrake.geometry import (
    ClippingRange,
    ColorRenderCamera,
    DepthRange,
    DepthRenderCamera,
    MakeRenderEngineVtk,
    RenderCameraCore,
    RenderEngineVtkParams,
)
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.sensors import CameraInfo, RgbdSensor

from cake_drake.errors import InputError

RENDERER = "vtk"
#: What a camera can ride on.
ATTACHMENTS = ("world", "panda_hand")


@dataclass
class Camera:
    """One camera (see the module's docstring for frames and conventions)."""

    name: str = "scene"
    attached_to: str = "world"  # world | panda_hand
    xyz: list[float] = field(default_factory=lambda: [1.35, 0.0, 1.0])  # m, in that frame
    #: A point to look at, in the same frame (empty: use rpy_deg).
    target: list[float] = field(default_factory=lambda: [0.3, 0.0, 0.0])
    rpy_deg: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    width: int = 224
    height: int = 224
    fov_y_deg: float = 60.0  # vertical field of view
    rate_hz: float = 10.0  # how often a policy or a recording samples it
    depth: bool = False  # also a depth image (m)


def default_cameras() -> list[Camera]:
    """A scene camera that frames the whole table, and a wrist camera on the hand that sees
    what the fingers are about to close on: 224 x 224 RGB at 10 Hz (OpenVLA's input)."""
    return [
        Camera(),
        Camera(
            name="wrist",
            attached_to="panda_hand",
            xyz=[0.09, 0.0, 0.02],  # behind the fingers, off the flange
            target=[0.0, 0.0, 0.2],  # 10 cm past the grasp point: a cube at pre-grasp
            fov_y_deg=70.0,
        ),
    ]


def look_at(eye: Sequence[float], target: Sequence[float], up=(0.0, 0.0, 1.0)) -> RigidTransform:
    """Camera pose (Drake camera frame: +z forward, +x right, +y down) at ``eye`` looking
    at ``target``, with ``up`` towards the top of the image."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, float))
    if np.linalg.norm(x) < 1e-9:  # looking along up: any right-hand side will do
        x = np.cross(z, [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return RigidTransform(RotationMatrix(np.column_stack([x, y, z])), eye)


def camera_pose(camera: Camera) -> RigidTransform:
    """``X_PC``: the camera in the frame it is attached to."""
    if camera.target:
        # On the hand, +x of the hand frame is "up" in the image (the hand points down).
        up = (0.0, 0.0, 1.0) if camera.attached_to == "world" else (-1.0, 0.0, 0.0)
        return look_at(camera.xyz, camera.target, up)
    return RigidTransform(RollPitchYaw(np.radians(camera.rpy_deg)), camera.xyz)


def check_cameras(cameras: Sequence[Camera], section: str = "cameras") -> None:
    """Refuse cameras that cannot work, before anything is built (one line, exit 2)."""
    names = [c.name for c in cameras]
    for c in cameras:
        where = f"{section}[{names.index(c.name)}] ({c.name})"
        if not c.name or not c.name.replace("_", "").isalnum():
            raise InputError(f"{where}: a camera's name is letters, digits and _")
        if names.count(c.name) > 1:
            raise InputError(f"{where}: two cameras named {c.name!r}")
        if c.attached_to not in ATTACHMENTS:
            raise InputError(
                f"{where}: attached_to {c.attached_to!r}; choose one of: {', '.join(ATTACHMENTS)}"
            )
        if not (16 <= c.width <= 4096 and 16 <= c.height <= 4096):
            raise InputError(f"{where}: {c.width} x {c.height} pixels; each side 16 to 4096")
        if not 5.0 <= c.fov_y_deg <= 170.0:
            raise InputError(f"{where}: fov_y_deg {c.fov_y_deg:g}; 5 to 170 degrees")
        if not 0.1 <= c.rate_hz <= 100.0:
            raise InputError(f"{where}: rate_hz {c.rate_hz:g}; 0.1 to 100 Hz")
        if len(c.xyz) != 3 or (c.target and len(c.target) != 3) or len(c.rpy_deg) != 3:
            raise InputError(f"{where}: xyz, target and rpy_deg are three numbers each")
        if c.target and np.linalg.norm(np.subtract(c.target, c.xyz)) < 1e-6:
            raise InputError(f"{where}: the camera stands at its own target")


#: Whether this process has made a VTK render engine. Its GL state does not survive a fork
#: (a forked child that renders waits forever for threads it does not have), so the
#: output helpers are not forked after one (cake_drake.outputs.worker).
engines_made = False


def render_engine():
    """A headless ``RenderEngineVtk`` (EGL), noted in :data:`engines_made`."""
    global engines_made
    engines_made = True
    return MakeRenderEngineVtk(RenderEngineVtkParams())


def add_cameras(
    builder: DiagramBuilder, scene, cameras: Sequence[Camera], prefix: str = "camera_"
) -> dict:
    """Add the VTK renderer and one ``RgbdSensor`` per camera, named ``prefix`` + its
    name; returns name -> sensor."""
    if not cameras:
        return {}
    sg, plant = scene.scene_graph, scene.plant
    if not sg.HasRenderer(RENDERER):
        try:
            sg.AddRenderer(RENDERER, render_engine())
        except RuntimeError as e:
            raise InputError(
                f"cameras: the headless renderer could not start ({str(e).splitlines()[0]}); "
                "install its libraries: apt-get install libegl1 libegl-mesa0 "
                "libgl1-mesa-dri libgbm1"
            ) from None
    sensors = {}
    for c in cameras:
        if c.attached_to == "world":
            parent = sg.world_frame_id()
        else:
            parent = plant.GetBodyFrameIdOrThrow(
                plant.GetBodyByName(c.attached_to, scene.hand).index()
            )
        core = RenderCameraCore(
            RENDERER,
            CameraInfo(c.width, c.height, np.radians(c.fov_y_deg)),
            ClippingRange(0.01, 5.0),
            RigidTransform(),
        )
        sensor = builder.AddNamedSystem(
            f"{prefix}{c.name}",
            RgbdSensor(
                parent,
                camera_pose(c),
                ColorRenderCamera(core, False),
                DepthRenderCamera(core, DepthRange(0.02, 4.9)),
            ),
        )
        builder.Connect(sg.get_query_output_port(), sensor.query_object_input_port())
        sensors[c.name] = sensor
    return sensors


def grab(sensors: dict, cameras: Sequence[Camera], root_context) -> dict[str, np.ndarray]:
    """Every camera's image now: ``name`` -> RGB (H x W x 3, uint8), and ``name.depth`` ->
    depth (H x W, float32 m) for a camera with ``depth``."""
    images = {}
    for c in cameras:
        sensor = sensors[c.name]
        context = sensor.GetMyContextFromRoot(root_context)
        rgba = sensor.color_image_output_port().Eval(context).data
        images[c.name] = np.array(rgba[:, :, :3], copy=True)
        if c.depth:
            depth = sensor.depth_image_32F_output_port().Eval(context).data
            images[f"{c.name}.depth"] = np.array(depth[:, :, 0], copy=True)
    return images


# EGL and OpenGL enums (EGL 1.5, OpenGL 1.0): the strings renderer_in_use reads.
_EGL_VENDOR = 0x3053
_GL_VENDOR, _GL_RENDERER, _GL_VERSION = 0x1F00, 0x1F01, 0x1F02


def renderer_in_use() -> dict[str, str | None]:
    """The GL implementation VTK renders with in this process, asked of its own context.

    After a render, VTK's EGL context stays current on the thread that rendered; its
    display names the EGL vendor (``Mesa Project``, ``NVIDIA``) and OpenGL names the
    device (``llvmpipe (LLVM ...)``: Mesa's software rasteriser, or the GPU's name). When
    no EGL context is current (nothing rendered on this thread yet), one 16 x 16 frame of
    an empty world is rendered first, through the same ``RenderEngineVtk``. Returns
    ``{"backend", "vendor", "device", "version"}``; the strings are None where EGL could
    not be asked (no libEGL, or VTK made no EGL context)."""
    info = _current_egl_context()
    if info is None:
        probe = _render_probe()  # keeps VTK's context alive while it is asked
        info = _current_egl_context()
        del probe
    unknown = {"vendor": None, "device": None, "version": None}
    return {"backend": "EGL" if info else None, **(info or unknown)}


def renderer_line() -> str:
    """:func:`renderer_in_use` as one line: ``renderer: EGL, Mesa Project, llvmpipe (...)``."""
    r = renderer_in_use()
    if r["backend"] is None:
        return "renderer: unknown (no EGL context)"
    return f"renderer: {r['backend']}, {r['vendor']}, {r['device']}, OpenGL {r['version']}"


def _current_egl_context() -> dict[str, str] | None:
    """Vendor, device and version of the EGL context current on this thread, or None."""
    try:
        egl = ctypes.CDLL("libEGL.so.1")  # the library VTK loaded: the same handle
    except OSError:
        return None
    egl.eglGetCurrentContext.restype = ctypes.c_void_p
    egl.eglGetCurrentDisplay.restype = ctypes.c_void_p
    egl.eglQueryString.restype = ctypes.c_char_p
    egl.eglQueryString.argtypes = [ctypes.c_void_p, ctypes.c_int]
    egl.eglGetProcAddress.restype = ctypes.c_void_p
    egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]
    display = egl.eglGetCurrentDisplay()
    if not egl.eglGetCurrentContext() or not display:
        return None
    address = egl.eglGetProcAddress(b"glGetString")
    if not address:
        return None
    gl_get_string = ctypes.CFUNCTYPE(ctypes.c_char_p, ctypes.c_uint)(address)

    def text(value: bytes | None) -> str | None:
        return value.decode(errors="replace") if value else None

    return {
        "vendor": text(egl.eglQueryString(display, _EGL_VENDOR)) or text(gl_get_string(_GL_VENDOR)),
        "device": text(gl_get_string(_GL_RENDERER)),
        "version": text(gl_get_string(_GL_VERSION)),
    }


def _render_probe():
    """Render one 16 x 16 frame of an empty world with ``RenderEngineVtk`` on this thread;
    returns what must stay alive for its context to stay current."""
    from pydrake.geometry import SceneGraph

    builder = DiagramBuilder()
    sg = builder.AddSystem(SceneGraph())
    try:
        sg.AddRenderer(RENDERER, render_engine())
    except RuntimeError:
        return None
    core = RenderCameraCore(
        RENDERER, CameraInfo(16, 16, 1.0), ClippingRange(0.1, 1.0), RigidTransform()
    )
    sensor = builder.AddSystem(
        RgbdSensor(
            sg.world_frame_id(),
            RigidTransform(),
            ColorRenderCamera(core, False),
            DepthRenderCamera(core, DepthRange(0.11, 0.9)),
        )
    )
    builder.Connect(sg.get_query_output_port(), sensor.query_object_input_port())
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    sensor.color_image_output_port().Eval(sensor.GetMyContextFromRoot(context))
    return diagram, context
