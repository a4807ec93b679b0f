"""A URDF's collision geometry gathered per link of the robot's chain, and points drawn on it.

:func:`link_geometry` reads every ``<collision>`` element of a URDF (meshes: STL, OBJ, DAE through
trimesh, found by :func:`resolve_mesh_path`; boxes, cylinders, spheres) and gathers them per link of the
robot's chain: link k is the child of joint k (0 the base), and geometry on links fixed to it is carried
into its frame. Geometry behind a movable joint that is not on the chain (a gripper's fingers, a jaw) is
swept over that joint's range and given to the chain link it hangs from, so that what is fitted to it
covers it wherever it is.

A :class:`LinkGeometry` draws points on its surface, area-weighted over its parts (primitives: on their
exact surfaces); :func:`_edge_points` draws them on the meshes' edges (the corners and rims area sampling
almost never hits) and :func:`_solid` voxelises the link's solid (each part filled on its own). The
sphere fit that uses them: :mod:`kinlearn.collision.spherize`.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..body.robot import Robot, _example_robot_data_dir, _origin, validate_urdf
from ..errors import MissingDependencyError, RobotDescriptionError

__all__ = ["LinkGeometry", "link_geometry", "resolve_mesh_path"]


@dataclass
class _Part:
    """One collision element in its chain link's frame: a triangle mesh (for the solid) and a way to
    draw points on its exact surface."""

    mesh: object  # trimesh.Trimesh, in the link frame
    kind: str  # "mesh", "box", "cylinder", "sphere"
    size: tuple  # box: extents; cylinder: (radius, length); sphere: (radius,)
    T: np.ndarray  # (4, 4) primitive frame in the link frame

    def area(self) -> float:
        return float(self.mesh.area)

    def sample(self, n: int, gen: np.random.Generator) -> np.ndarray:
        if n <= 0:
            return np.zeros((0, 3))
        if self.kind == "sphere":
            v = gen.normal(size=(n, 3))
            local = self.size[0] * v / np.linalg.norm(v, axis=1, keepdims=True)
        elif self.kind == "cylinder":
            r, h = self.size
            side, cap = 2 * math.pi * r * h, math.pi * r * r
            on_side = gen.random(n) < side / (side + 2 * cap)
            a = gen.random(n) * 2 * math.pi
            rho = np.where(on_side, r, r * np.sqrt(gen.random(n)))
            z = np.where(on_side, (gen.random(n) - 0.5) * h, np.where(gen.random(n) < 0.5, -h / 2, h / 2))
            local = np.stack([rho * np.cos(a), rho * np.sin(a), z], axis=1)
        else:
            local = None
        if local is not None:
            return local @ self.T[:3, :3].T + self.T[:3, 3]
        # a triangle mesh (boxes too: their triangles are their faces exactly), area-weighted
        tri = np.asarray(self.mesh.triangles)
        w = np.asarray(self.mesh.area_faces, dtype=np.float64)
        face = gen.choice(len(tri), size=n, p=w / w.sum())
        u, v = gen.random(n), gen.random(n)
        flip = u + v > 1
        u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
        t = tri[face]
        return t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])


@dataclass
class LinkGeometry:
    """The collision geometry of one chain link (``index`` 0 = the base), in its frame."""

    index: int
    name: str  # the URDF link the spheres are written on
    parts: list = field(default_factory=list)

    def sample(self, n: int, gen: np.random.Generator) -> np.ndarray:
        """``(n, 3)`` points on the surface, area-weighted over the parts."""
        areas = np.array([p.area() for p in self.parts])
        counts = gen.multinomial(n, areas / areas.sum())
        return np.concatenate([p.sample(int(c), gen) for p, c in zip(self.parts, counts, strict=True)])


def _trimesh():
    try:
        import trimesh
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise MissingDependencyError("fitting spheres needs trimesh: pip install trimesh") from exc
    return trimesh


def resolve_mesh_path(filename: str, urdf_path: Path | None, package_dirs: tuple = ()) -> Path:
    """The file a URDF's ``<mesh filename=...>`` names: ``package://PKG/rest`` is looked up in
    ``package_dirs`` (folders holding PKG, or PKG itself), the folders above the URDF, ``$ROS_PACKAGE_PATH``
    and example-robot-data's; ``file://`` and plain paths are taken relative to the URDF."""
    import os

    if filename.startswith("file://"):
        filename = filename[len("file://") :]
    here = urdf_path.parent if urdf_path is not None else Path.cwd()
    if not filename.startswith("package://"):
        p = Path(filename)
        p = p if p.is_absolute() else here / p
        if p.is_file():
            return p
        raise RobotDescriptionError(f"the mesh {filename!r} is not a file (looked at {p})")
    rest = filename[len("package://") :]
    pkg, _, sub = rest.partition("/")
    roots = [Path(d) for d in package_dirs]
    roots += [here.resolve(), *here.resolve().parents]
    roots += [Path(d) for d in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if d]
    tried = []
    for root in roots:
        for cand in (root / pkg / sub, root / sub if root.name == pkg else None):
            if cand is not None:
                tried.append(cand)
                if cand.is_file():
                    return cand
    if pkg == "example-robot-data":
        try:
            erd = _example_robot_data_dir().parent  # .../share/example-robot-data
            cand = erd / sub
            if cand.is_file():
                return cand
        except RobotDescriptionError:
            pass
    raise RobotDescriptionError(
        f"the mesh {filename!r} was not found (package {pkg!r}); pass package_dirs=[folder holding {pkg}] "
        f"(--package-dir), or set ROS_PACKAGE_PATH"
    )


def _load_mesh(path: Path):
    trimesh = _trimesh()
    if path.suffix.lower() == ".dae":
        try:
            import collada  # noqa: F401
        except ImportError as exc:
            raise MissingDependencyError(
                f"reading the COLLADA mesh {path} needs pycollada: pip install pycollada"
            ) from exc
    try:
        loaded = trimesh.load(str(path), force="mesh", process=True)
    except Exception as exc:  # trimesh raises many kinds for a file it cannot read
        raise RobotDescriptionError(f"the mesh {path} could not be read: {exc}") from exc
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise RobotDescriptionError(f"the mesh {path} holds no triangles")
    return loaded


def _part(col: ET.Element, T_link: np.ndarray, urdf_path, package_dirs, what: str) -> _Part | None:
    trimesh = _trimesh()
    geom = col.find("geometry")
    if geom is None or len(geom) == 0:
        raise RobotDescriptionError(f"{what}: a <collision> without <geometry>")
    g = geom[0]
    T = T_link @ _origin(col.find("origin"), what)
    if g.tag == "mesh":
        mesh = _load_mesh(resolve_mesh_path(g.get("filename", ""), urdf_path, package_dirs)).copy()
        scale = [float(s) for s in (g.get("scale") or "1 1 1").split()]
        S = np.diag([*(scale * 3 if len(scale) == 1 else scale), 1.0])
        mesh.apply_transform(T @ S)
        return _Part(mesh, "mesh", (), T)
    if g.tag == "box":
        ext = [float(s) for s in g.get("size", "").split()]
        if len(ext) != 3 or min(ext) <= 0:
            raise RobotDescriptionError(f"{what}: a box needs size='x y z' > 0, got {g.get('size')!r}")
        mesh = trimesh.creation.box(extents=ext)
        mesh.apply_transform(T)
        return _Part(mesh, "box", tuple(ext), T)
    if g.tag == "cylinder":
        r, h = float(g.get("radius", "nan")), float(g.get("length", "nan"))
        if not (r > 0 and h > 0):
            raise RobotDescriptionError(f"{what}: a cylinder needs radius and length > 0")
        mesh = trimesh.creation.cylinder(radius=r, height=h, sections=64)
        mesh.apply_transform(T)
        return _Part(mesh, "cylinder", (r, h), T)
    if g.tag == "sphere":
        r = float(g.get("radius", "nan"))
        if not r > 0:
            raise RobotDescriptionError(f"{what}: a sphere needs radius > 0")
        mesh = trimesh.creation.icosphere(subdivisions=3, radius=r)
        mesh.apply_transform(T)
        return _Part(mesh, "sphere", (r,), T)
    raise RobotDescriptionError(f"{what}: collision geometry <{g.tag}> is not one kinlearn reads")


def _joint_motion(el: ET.Element, q: float) -> np.ndarray:
    """The motion of a joint element at displacement ``q`` (about / along its axis)."""
    axis_el = el.find("axis")
    axis = np.array([1.0, 0.0, 0.0])
    if axis_el is not None and axis_el.get("xyz"):
        axis = np.array([float(s) for s in axis_el.get("xyz").split()])
        axis = axis / np.linalg.norm(axis)
    M = np.eye(4)
    if el.get("type") == "prismatic":
        M[:3, 3] = axis * q
    else:
        K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        M[:3, :3] = np.eye(3) + math.sin(q) * K + (1 - math.cos(q)) * K @ K
    return M


def _sweep_values(el: ET.Element, n: int) -> np.ndarray:
    lim = el.find("limit")
    if el.get("type") == "continuous" or lim is None or lim.get("lower") is None:
        lo, hi = -math.pi, math.pi
    else:
        lo, hi = float(lim.get("lower")), float(lim.get("upper"))
    return np.linspace(lo, hi, n)


def link_geometry(
    robot: Robot, urdf: str | Path | None = None, package_dirs: tuple = (), sweep: int = 9
) -> list[LinkGeometry]:
    """The collision geometry of ``robot``'s URDF (or of ``urdf``, the same joint names) gathered per
    chain link, each in its frame (see the module docstring). Links above the base (a world link) are
    left out. Raises :class:`~kinlearn.errors.RobotDescriptionError` when no chain link has any."""
    path = Path(urdf) if urdf is not None else robot.urdf_path
    data = path.read_bytes() if path is not None else robot.urdf
    root = validate_urdf(data, robot.name)
    joints_by_child = {el.find("child").get("link"): el for el in root.findall("joint")}
    index = {j.name: k + 1 for k, j in enumerate(robot.joints)}
    first = next(el for el in root.findall("joint") if el.get("name") == robot.joints[0].name)
    base = first.find("parent").get("link")
    names = [base] + [
        next(el for el in root.findall("joint") if el.get("name") == j.name).find("child").get("link")
        for j in robot.joints
    ]
    groups = [LinkGeometry(k, n) for k, n in enumerate(names)]
    for link in root.findall("link"):
        cols = link.findall("collision")
        if not cols:
            continue
        # walk up to the chain link, composing fixed origins; joints off the chain become sweeps
        frames = [np.eye(4)]
        cur, k = link.get("name"), None
        while True:
            if cur == base:
                k = 0
                break
            el = joints_by_child.get(cur)
            if el is None:
                break  # above the base
            jname = el.get("name")
            if jname in index:
                k = index[jname]
                break
            O = _origin(el.find("origin"), f"joint {jname}")
            if el.get("type") == "fixed":
                frames = [O @ F for F in frames]
            elif el.get("type") in ("revolute", "continuous", "prismatic"):
                frames = [O @ _joint_motion(el, q) @ F for q in _sweep_values(el, sweep) for F in frames]
                if len(frames) > 4 * sweep * sweep:
                    raise RobotDescriptionError(
                        f"link {link.get('name')!r} hangs behind more than two joints off the chain; "
                        "fix them in the URDF (type='fixed') before fitting spheres"
                    )
            else:
                raise RobotDescriptionError(
                    f"link {link.get('name')!r} sits behind joint {jname!r} of type {el.get('type')!r}; "
                    "fix it in the URDF before fitting spheres"
                )
            cur = el.find("parent").get("link")
        if k is None:
            continue
        for c, col in enumerate(cols):
            for F in frames:
                part = _part(col, F, path, package_dirs, f"link {link.get('name')!r}, collision {c}")
                if part is not None:
                    groups[k].parts.append(part)
    if not any(g.parts for g in groups):
        raise RobotDescriptionError(
            f"{robot.name}: no link of the chain carries <collision> geometry; add collision meshes or "
            "primitives to the URDF's links (or pass a URDF that has them)"
        )
    return groups


def _solid(group: LinkGeometry, voxels: int):
    """Filled voxel centres ``(V, 3)`` of the link's solid and the voxel pitch."""
    trimesh = _trimesh()
    mesh = trimesh.util.concatenate([p.mesh for p in group.parts])
    pitch = max(float(mesh.extents.max()) / voxels, 1e-4)
    centres = []
    for p in group.parts:  # each part filled on its own: the union of solids, not of shells
        try:
            vox = p.mesh.voxelized(pitch).fill()
            centres.append(np.asarray(vox.points))
        except Exception:  # a degenerate part: its surface points stand in
            centres.append(np.asarray(p.mesh.vertices))
    pts = np.concatenate(centres)
    # one centre per voxel of a common grid
    key = np.round(pts / pitch).astype(np.int64)
    _, first = np.unique(key, axis=0, return_index=True)
    return pts[np.sort(first)], pitch


def _edge_points(group: LinkGeometry, n: int, gen: np.random.Generator) -> np.ndarray:
    """``(n, 3)`` points on the parts' mesh edges, length-weighted."""
    segs = np.concatenate([np.asarray(p.mesh.vertices)[np.asarray(p.mesh.edges_unique)] for p in group.parts])
    length = np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1)
    if n <= 0 or length.sum() <= 0:
        return np.zeros((0, 3))
    pick = gen.choice(len(segs), size=n, p=length / length.sum())
    t = gen.random(n)[:, None]
    return segs[pick, 0] + t * (segs[pick, 1] - segs[pick, 0])
