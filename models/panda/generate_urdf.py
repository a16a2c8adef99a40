"""Write the Panda URDFs in this folder from the published kinematics and the mesh geometry.

Run once by hand (``pip install -e .[models]``, then ``python models/panda/generate_urdf.py``);
the URDFs and meshes it writes are committed.

Why generate: the only offline Panda description on PyPI (``pybullet_data/franka_panda``)
has placeholder inertias (0.1 kg m^2 on every link), zero-mass links, no actuators and a
few non-datasheet limits. Here we keep its kinematics (Franka's modified-DH values) and
meshes, and write:

* ``panda_arm.urdf``: links 0-7, datasheet joint limits (position, velocity, effort),
  one actuator per joint, inertias of the collision mesh as a uniform solid scaled to the
  link's mass (about its own centre of mass), collision meshes as convex hulls.
* ``panda_hand.urdf``: hand and two prismatic fingers with actuators; the fingers touch
  the world only through four small spheres on each fingertip (a finger mesh touches a
  cube at a single point, so the cube would pivot in the grasp).
* ``panda_hand_welded.urdf``: the same hand with the fingers fixed, for the 7-DOF
  control plant that ``InverseDynamicsController`` needs (it rejects unactuated DOFs).

Every mesh a run loads is kept here, so a run needs nothing from the wheel: the collision
meshes' convex hulls in ``collision/`` (:func:`write_collision_hulls`), and simplified
visual meshes in ``meshes/`` (:func:`write_visual_meshes`): the wheel's own do not load
in a browser's Meshcat, and their ~100,000 triangles make every picture slow.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pybullet_data
from pydrake.geometry import Convex, Mesh
from pydrake.multibody.tree import CalcSpatialInertia

HERE = Path(__file__).resolve().parent
MESHES = Path(pybullet_data.getDataPath()) / "franka_panda" / "meshes"
#: The collision meshes' convex hulls, kept here (see :func:`write_collision_hulls`).
HULLS = HERE / "collision"
HULLS_PKG = "package://cake_drake/panda/collision"

# Link masses (kg) as published with the pybullet_data model.
MASS = {
    "link0": 2.9, "link1": 2.7, "link2": 2.73, "link3": 2.04, "link4": 2.08,
    "link5": 3.0, "link6": 1.3, "link7": 0.2, "hand": 0.81, "finger": 0.1,
}  # fmt: skip

# Joint origins (parent frame) and datasheet limits: lower, upper (rad), velocity (rad/s),
# effort (N m), acceleration (rad/s^2, as drake:acceleration, which Drake's parser reads
# into the plant). The kinematics are Franka's modified-DH values.
JOINTS = [
    # xyz,                  rpy,            lower,   upper,   vel,   effort, accel
    ((0, 0, 0.333),      (0, 0, 0),         -2.8973, 2.8973, 2.175, 87.0, 15.0),
    ((0, 0, 0),          (-np.pi / 2, 0, 0), -1.7628, 1.7628, 2.175, 87.0, 7.5),
    ((0, -0.316, 0),     (np.pi / 2, 0, 0), -2.8973, 2.8973, 2.175, 87.0, 10.0),
    ((0.0825, 0, 0),     (np.pi / 2, 0, 0), -3.0718, -0.0698, 2.175, 87.0, 12.5),
    ((-0.0825, 0.384, 0), (-np.pi / 2, 0, 0), -2.8973, 2.8973, 2.61, 12.0, 15.0),
    ((0, 0, 0),          (np.pi / 2, 0, 0), -0.0175, 3.7525, 2.61, 12.0, 20.0),
    ((0.088, 0, 0),      (np.pi / 2, 0, 0), -2.8973, 2.8973, 2.61, 12.0, 20.0),
]  # fmt: skip

# Visual meshes, all kept in meshes/ here (Apache-2.0, as the wheel: LICENSE.txt here). Links 0
# and 7 have no detailed mesh in the wheel: their collision meshes serve, copied without the
# material file they name and the wheel lacks (a warning on every load). The others are
# the wheel's detailed meshes rewritten by write_visual_meshes().
OWN_MESHES = HERE / "meshes"
#: The links whose collision mesh touches the world (the fingers touch it through pads).
HULL_LINKS = ("link0", "link1", "link2", "link3", "link4", "link5", "link6", "link7", "hand")
PLAIN = ("link0", "link7")
DETAILED = ("link1", "link2", "link3", "link4", "link5", "link6", "hand", "finger")
VISUAL = {name: f"package://cake_drake/panda/meshes/{name}.obj" for name in PLAIN + DETAILED}

FINGER_ORIGIN_Z = 0.0584  # finger frames above the hand frame
FINGER_TRAVEL = 0.04  # each finger, m
FINGER_EFFORT = 40.0  # N, the bound on the squeeze each finger can apply
FINGER_VELOCITY = 0.2  # m/s
PAD_RADIUS = 0.003
PAD_STIFFNESS = 1e5  # N/m: rubber-like pads, about 0.1 mm in at a 20 N squeeze
# Pad centres in the left finger's frame (inner face is the y = 0 plane of the mesh).
PAD_XZ = [(-0.006, 0.040), (0.006, 0.040), (-0.006, 0.050), (0.006, 0.050)]


def _fmt(v) -> str:
    return " ".join(f"{x:.6g}" for x in v)


def inertial(name: str) -> str:
    """``<inertial>`` of the collision mesh as a uniform solid with the link's mass."""
    m = MASS[name]
    unit = CalcSpatialInertia(Mesh(str(MESHES / "collision" / f"{name}.obj")), 1.0)
    com = unit.get_com()
    Icm = unit.Shift(com).CalcRotationalInertia().CopyToFullMatrix3() * (m / unit.get_mass())
    return (
        f'    <inertial>\n      <origin xyz="{_fmt(com)}" rpy="0 0 0"/>\n'
        f'      <mass value="{m}"/>\n'
        f'      <inertia ixx="{Icm[0, 0]:.6g}" ixy="{Icm[0, 1]:.6g}" ixz="{Icm[0, 2]:.6g}" '
        f'iyy="{Icm[1, 1]:.6g}" iyz="{Icm[1, 2]:.6g}" izz="{Icm[2, 2]:.6g}"/>\n'
        f"    </inertial>\n"
    )


def visual(name: str, rpy: str = "0 0 0") -> str:
    mesh = VISUAL[name]
    colour = (
        '      <material><color rgba="0.95 0.95 0.95 1"/></material>\n' if name in PLAIN else ""
    )
    return (
        f'    <visual>\n      <origin xyz="0 0 0" rpy="{rpy}"/>\n'
        f'      <geometry><mesh filename="{mesh}"/></geometry>\n{colour}'
        f"    </visual>\n"
    )


def write_collision_hulls() -> None:
    """The convex hull of each collision mesh of the wheel, as Drake computes it: what a
    ``drake:declare_convex`` mesh collides as anyway. Drake then parses a few hundred
    vertices per link instead of thousands (about 40 ms less for each world built), and
    a run needs no file from the wheel. Vertices are written exactly (``repr``), so the
    hull of the hull is the same solid; the inertias still come from the full meshes."""
    HULLS.mkdir(exist_ok=True)
    for name in HULL_LINKS:
        source = MESHES / "collision" / f"{name}.obj"
        origin = f"pybullet_data/franka_panda/meshes/collision/{name}.obj"
        hull = Convex(str(source)).GetConvexHull()
        lines = [f"# {name}: the convex hull of {origin}"]
        for i in range(hull.num_vertices()):
            lines.append("v " + " ".join(repr(float(x)) for x in hull.vertex(i)))
        data, k = list(hull.face_data()), 0
        while k < len(data):
            n = data[k]
            lines.append("f " + " ".join(str(v + 1) for v in data[k + 1 : k + 1 + n]))
            k += n + 1
        (HULLS / f"{name}.obj").write_text("\n".join(lines) + "\n")


def copy_plain_meshes() -> None:
    """Copy the collision meshes that serve as visuals, minus their dangling ``mtllib``."""
    OWN_MESHES.mkdir(exist_ok=True)
    for name in PLAIN:
        lines = (MESHES / "collision" / f"{name}.obj").read_text().splitlines(keepends=True)
        kept = [line for line in lines if not line.startswith(("mtllib", "usemtl"))]
        (OWN_MESHES / f"{name}.obj").write_text("".join(kept))


def write_visual_meshes(decimals: int = 4, keep: float = 0.12, crease_deg: float = 35.0) -> None:
    """Rewrite the wheel's detailed visual meshes so that every viewer draws them, compactly.

    Meshcat's browser viewer merges the parts of an OBJ into one geometry and draws nothing
    when the parts differ in their attributes: in the wheel's ``hand``, ``link5`` and
    ``link6`` some parts have texture coordinates and others none, and two have stray line
    elements, so those three were missing from every Meshcat view and replay. Each copy here
    has triangles with normals only (Drake's VTK renderer needs normals), positions to
    ``decimals`` places (0.1 mm by default), normals to 3, one part per colour, and
    no texture: the texture (``colors.png``) is a white sheet with one grey decal, so each
    face's texel is baked into its part's diffuse colour.

    Each part of over 1,000 triangles is simplified to ``keep`` of them (quadric edge collapse, the
    ``fast-simplification`` package: ``pip install -e .[models]``): the wheel's ~100,000
    triangles are far more than an 800 x 600 picture or a browser view shows, and loading
    them is most of what a picture costs. Normals are recomputed per corner, smooth across
    edges sharper than ``crease_deg`` and creased beyond.
    """
    import fast_simplification
    import matplotlib.image

    OWN_MESHES.mkdir(exist_ok=True)
    texture = matplotlib.image.imread(MESHES / "visual" / "colors.png")[..., :3]
    decal = texture.min(axis=2) < 0.8
    decal_rgb = texture[decal].mean(axis=0)
    h, w = decal.shape

    def number(x: float, places: int) -> str:
        text = f"{round(x, places) + 0.0:.{places}f}".rstrip("0").rstrip(".")
        return "0" if text in ("", "-0") else text

    for name in DETAILED:
        materials = _read_mtl(MESHES / "visual" / f"{name}.mtl")
        points: list[list[float]] = []
        uvs: list[tuple[float, float]] = []
        parts: dict[tuple[float, ...], list[list[int]]] = {}  # colour -> triangles
        material = ((1.0, 1.0, 1.0), False)
        for line in (MESHES / "visual" / f"{name}.obj").read_text().splitlines():
            tag, _, rest = line.partition(" ")
            if tag == "v":
                points.append([float(x) for x in rest.split()[:3]])
            elif tag == "vt":
                u, v = (float(x) for x in rest.split()[:2])
                uvs.append((u, v))
            elif tag == "usemtl":
                material = materials[rest.strip()]
            elif tag == "f":
                corners = [c.split("/") for c in rest.split()]
                kd, textured = material
                rgb = kd
                if textured and all(len(c) > 1 and c[1] for c in corners):
                    u, v = np.mean([uvs[int(c[1]) - 1] for c in corners], axis=0)
                    row = min(h - 1, max(0, int((1.0 - v) * h)))
                    col = min(w - 1, max(0, int(u * w)))
                    if decal[row, col]:
                        rgb = tuple(k * t for k, t in zip(kd, decal_rgb, strict=True))
                key = tuple(round(float(x), 3) for x in rgb)
                parts.setdefault(key, []).append([int(c[0]) - 1 for c in corners])
            # normals (recomputed), "l" (stray line elements), "o", "g", "s": dropped.
        vertices = np.array(points)
        positions: list[str] = []
        normal_ids: dict[str, int] = {}  # rounded normal -> its 1-based index
        faces: dict[tuple[float, ...], list[str]] = {}
        for key, triangles in parts.items():
            used, local = np.unique(np.array(triangles), return_inverse=True)
            p, t = vertices[used], local.reshape(-1, 3)
            if len(t) > 1000:  # small parts (the fingers, the decals) are kept whole
                p, t = fast_simplification.simplify(p, t, target_count=int(len(t) * keep))
            offset = len(positions)
            positions += ["v " + " ".join(number(x, decimals) for x in xyz) for xyz in p]
            normals = _corner_normals(p, t, crease_deg)
            for tri, corner_normals in zip(t, normals, strict=True):
                ids = []
                for n in corner_normals:
                    text = " ".join(number(x, 3) for x in n)
                    ids.append(normal_ids.setdefault(text, len(normal_ids) + 1))
                corners = (f"{offset + int(i) + 1}//{k}" for i, k in zip(tri, ids, strict=True))
                faces.setdefault(key, []).append("f " + " ".join(corners))
        source = f"pybullet_data/franka_panda/meshes/visual/{name}"
        mtl = [f"# {name}: the colours of {source}.mtl, texture baked in"]
        obj = [
            f"# {name}: {source}.obj simplified by models/panda/generate_urdf.py",
            f"mtllib {name}.mtl",
            *positions,
            *(f"vn {n}" for n in normal_ids),
        ]
        for k, (rgb, lines) in enumerate(sorted(faces.items(), reverse=True)):
            mtl += [f"newmtl {name}_{k}", "Kd " + " ".join(f"{x:.3f}" for x in rgb)]
            obj += [f"o {name}_{k}", f"usemtl {name}_{k}", *lines]
        (OWN_MESHES / f"{name}.mtl").write_text("\n".join(mtl) + "\n")
        (OWN_MESHES / f"{name}.obj").write_text("\n".join(obj) + "\n")


def _corner_normals(points: np.ndarray, triangles: np.ndarray, crease_deg: float) -> np.ndarray:
    """(n, 3, 3) unit normals at each triangle's corners: the area-weighted mean of the
    normals of the triangles around that corner's vertex that meet this one at less than
    ``crease_deg``, so smooth surfaces shade smoothly and sharp edges stay sharp."""
    a, b, c = (points[triangles[:, k]] for k in range(3))
    weighted = np.cross(b - a, c - a)  # length: twice the area
    unit = weighted / np.maximum(np.linalg.norm(weighted, axis=1, keepdims=True), 1e-12)
    around: dict[int, list[int]] = {}
    for f, tri in enumerate(triangles):
        for v in tri:
            around.setdefault(int(v), []).append(f)
    cos_crease = np.cos(np.radians(crease_deg))
    out = np.empty((len(triangles), 3, 3))
    for f, tri in enumerate(triangles):
        for k, v in enumerate(tri):
            near = np.array(around[int(v)])
            near = near[unit[near] @ unit[f] >= cos_crease]
            n = weighted[near].sum(axis=0)
            out[f, k] = n / max(np.linalg.norm(n), 1e-12)
    return out


def _read_mtl(path: Path) -> dict[str, tuple[tuple[float, ...], bool]]:
    """Material name -> (diffuse colour, textured?) from an MTL file."""
    out: dict[str, tuple[tuple[float, ...], bool]] = {}
    name = None
    for line in path.read_text().splitlines():
        tag, _, rest = line.strip().partition(" ")
        if tag == "newmtl":
            name = rest.strip()
            out[name] = ((1.0, 1.0, 1.0), False)
        elif tag == "Kd" and name:
            out[name] = (tuple(float(x) for x in rest.split()), out[name][1])
        elif tag == "map_Kd" and name:
            out[name] = (out[name][0], True)
    return out


def convex_collision(name: str) -> str:
    return (
        f"    <collision>\n"
        f'      <geometry><mesh filename="{HULLS_PKG}/{name}.obj">'
        f"<drake:declare_convex/></mesh></geometry>\n"
        f"    </collision>\n"
    )


def arm() -> str:
    out = ['<?xml version="1.0"?>\n<robot name="panda" xmlns:drake="http://drake.mit.edu">\n']
    for i in range(8):
        name = f"link{i}"
        out.append(f'  <link name="panda_{name}">\n')
        out.append(inertial(name) + visual(name) + convex_collision(name))
        out.append("  </link>\n")
    for i, (xyz, rpy, lo, hi, vel, effort, acc) in enumerate(JOINTS, start=1):
        out.append(
            f'  <joint name="panda_joint{i}" type="revolute">\n'
            f'    <origin xyz="{_fmt(xyz)}" rpy="{_fmt(rpy)}"/>\n'
            f'    <parent link="panda_link{i - 1}"/>\n    <child link="panda_link{i}"/>\n'
            f'    <axis xyz="0 0 1"/>\n'
            f'    <limit lower="{lo}" upper="{hi}" velocity="{vel}" effort="{effort}"\n'
            f'           drake:acceleration="{acc}"/>\n'
            f"  </joint>\n"
            f'  <transmission name="panda_transmission{i}" type="SimpleTransmission">\n'
            f'    <joint name="panda_joint{i}"/>\n    <actuator name="panda_motor{i}"/>\n'
            f"  </transmission>\n"
        )
    out.append("</robot>\n")
    return "".join(out)


def finger_link(side: str, sign: int, with_pads: bool) -> str:
    # The right finger is the left one turned half a turn about z.
    rpy = "0 0 0" if sign > 0 else "0 0 3.14159265359"
    out = [f'  <link name="panda_{side}finger">\n', inertial("finger"), visual("finger", rpy)]
    if with_pads:
        for k, (x, z) in enumerate(PAD_XZ):
            out.append(
                f'    <collision name="pad{k}">\n'
                f'      <origin xyz="{sign * x:.6g} {sign * PAD_RADIUS:.6g} {z:.6g}"/>\n'
                f'      <geometry><sphere radius="{PAD_RADIUS}"/></geometry>\n'
                f"      <drake:proximity_properties>\n"
                f'        <drake:mu_dynamic value="1.0"/>\n        <drake:mu_static value="1.0"/>\n'
                f'        <drake:point_contact_stiffness value="{PAD_STIFFNESS:g}"/>\n'
                f'        <drake:hunt_crossley_dissipation value="5"/>\n'
                f"      </drake:proximity_properties>\n"
                f"    </collision>\n"
            )
    out.append("  </link>\n")
    return "".join(out)


def hand(fingers_move: bool) -> str:
    name = "panda_hand" if fingers_move else "panda_hand_welded"
    out = [f'<?xml version="1.0"?>\n<robot name="{name}" xmlns:drake="http://drake.mit.edu">\n']
    out.append('  <link name="panda_hand">\n' + inertial("hand") + visual("hand"))
    out.append(convex_collision("hand") + "  </link>\n")
    for side, sign, axis in (("left", 1, "0 1 0"), ("right", -1, "0 -1 0")):
        out.append(finger_link(side, sign, with_pads=fingers_move))
        joint = f"panda_finger_joint{1 if sign > 0 else 2}"
        if fingers_move:
            out.append(
                f'  <joint name="{joint}" type="prismatic">\n'
                f'    <origin xyz="0 0 {FINGER_ORIGIN_Z}" rpy="0 0 0"/>\n'
                f'    <parent link="panda_hand"/>\n    <child link="panda_{side}finger"/>\n'
                f'    <axis xyz="{axis}"/>\n'
                f'    <limit lower="0" upper="{FINGER_TRAVEL}" velocity="{FINGER_VELOCITY}" '
                f'effort="{FINGER_EFFORT}"/>\n'
                f"  </joint>\n"
                f'  <transmission name="{joint}_transmission" type="SimpleTransmission">\n'
                f'    <joint name="{joint}"/>\n    <actuator name="{joint}_motor"/>\n'
                f"  </transmission>\n"
            )
        else:
            # Fingers held half open: their mass is what the control plant needs.
            out.append(
                f'  <joint name="{joint}" type="fixed">\n'
                f'    <origin xyz="0 {sign * 0.02} {FINGER_ORIGIN_Z}" rpy="0 0 0"/>\n'
                f'    <parent link="panda_hand"/>\n    <child link="panda_{side}finger"/>\n'
                f"  </joint>\n"
            )
    out.append("</robot>\n")
    return "".join(out)


def main() -> None:
    copy_plain_meshes()
    write_collision_hulls()
    write_visual_meshes()
    (HERE / "panda_arm.urdf").write_text(arm())
    (HERE / "panda_hand.urdf").write_text(hand(fingers_move=True))
    (HERE / "panda_hand_welded.urdf").write_text(hand(fingers_move=False))
    print(f"wrote panda_arm.urdf, panda_hand.urdf, panda_hand_welded.urdf in {HERE}")


if __name__ == "__main__":
    main()
