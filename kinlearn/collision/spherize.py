"""Collision spheres fitted to a URDF's own collision geometry.

:func:`spherize` reads every ``<collision>`` element of a URDF (meshes: STL, OBJ, DAE through trimesh;
boxes, cylinders, spheres) and gathers them per link of the robot's chain: link k is the child of joint
k (0 the base), and geometry on links fixed to it is carried into its frame. Geometry behind a movable
joint that is not on the chain (a gripper's fingers, a jaw) is swept over that joint's range and given
to the chain link it hangs from, so the spheres cover it wherever it is.

For each chain link a small set of spheres is chosen that **covers** the link's surface:

1. surface points are drawn area-weighted (primitives: on their exact surfaces), with the meshes'
   vertices and points on their edges (corners and rims, which area sampling almost never hits);
2. the link's solid is voxelised (surface voxels, interior filled); its filled voxel centres are the
   candidate sphere centres, and its filled volume is what a sphere's excess volume is measured
   against;
3. a weighted greedy set cover picks, among candidate centres × a geometric ladder of radii, the
   sphere with the lowest cost per newly covered point, cost = the sphere's volume outside the solid +
   a fixed price per sphere (``sphere_price`` times the link's solid volume): few spheres, little
   excess. Greedy set cover is within a factor ln(points) of the optimal cover, needs no tuning per
   link and is deterministic;
4. redundant spheres are dropped and each sphere shrunk to the farthest point only it covers, then a
   second, denser sample is checked and any point left outside grows the sphere that needs the least
   growth to hold it.

Why this and not k-means then radius growth: k-means puts centres where the points are (the
surface), so covering spheres are centred on the surface and half of each lies outside; candidate
centres inside the solid and a cost in excess volume choose spheres that sit within the link.

Self-collision: sphere pairs on adjacent links are never checked (the body's rule), and link pairs
to leave out are taken from an SRDF's ``disable_collisions`` when one is given, from the fitted
spheres themselves (link pairs whose spheres touch in every sampled configuration) and from the meshes
(link pairs whose meshes touch in none, as an SRDF generator finds its "Never" pairs: fitted spheres
are fatter than the meshes, and near a joint they may overlap where the meshes never do).

:func:`write_spherized_urdf` writes the spheres in the format of the shipped spherized URDFs (one
``<collision><geometry><sphere>`` per sphere, in the frame of its chain link; the rest of the URDF
unchanged but for its old collision elements); :func:`write_sphere_model` writes that file with a
``collision_spheres.json`` beside it, which ``register_robot(spheres=...)`` reads as either.
"""

from __future__ import annotations

import json
import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from ..body.robot import Robot, _example_robot_data_dir, _origin, validate_urdf
from ..errors import ConfigError, MissingDependencyError, RobotDescriptionError
from .mesh import MeshBody, chain_link_of

__all__ = [
    "LinkGeometry",
    "SphereFit",
    "SpherizeConfig",
    "coverage",
    "fit_link",
    "link_geometry",
    "spherize",
    "srdf_disabled_links",
    "write_sphere_model",
    "write_spherized_urdf",
]


@dataclass(frozen=True)
class SpherizeConfig:
    """How spheres are fitted (see the module docstring).

    ``fit_points``: surface points per link the cover is chosen for; ``check_points``: a second sample
    every point of which ends inside a sphere; ``voxels``: voxels along the link's longest side;
    ``candidates``: candidate centres per link at most; ``radii``: radii tried per centre;
    ``sphere_price``: the cost of one more sphere, as a share of the link's solid volume (higher: fewer,
    larger spheres); ``sweep``: positions a joint off the chain is swept over; ``tolerance`` (m): how far
    outside a sphere a checked point may lie and count as covered in :func:`coverage`'s report;
    ``samples``: configurations the always-touching link pairs are found from (by the spheres) and, with
    ``never``, the link pairs whose collision meshes never touch (by coal: what an SRDF generator leaves
    out as "Never"; the mesh check keeps checking them).
    """

    fit_points: int = 3000
    check_points: int = 40000
    voxels: int = 32
    candidates: int = 700
    radii: int = 24
    sphere_price: float = 0.5
    sweep: int = 9
    tolerance: float = 0.002
    samples: int = 2000
    never: bool = True
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("fit_points", "check_points", "voxels", "candidates", "radii", "sweep", "samples"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 2:
                raise ConfigError(f"SpherizeConfig.{name} must be an integer ≥ 2, got {v!r}")
        for name in ("sphere_price", "tolerance"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ConfigError(f"SpherizeConfig.{name} must be a finite number ≥ 0, got {v!r}")


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


@dataclass
class SphereFit:
    """Spheres fitted to a robot: ``spheres`` rows ``[link, x, y, z, r]`` (link k's frame, base 0
    first), the chain ``links`` (URDF link names, index k), the ``excluded_link_pairs`` a self-collision
    check leaves out (with ``why`` each), and per link the figures measured while fitting."""

    robot: str
    spheres: np.ndarray
    links: list[str]
    excluded_link_pairs: list[tuple[int, int]]
    why: list[str]
    report: list[dict]
    config: SpherizeConfig


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


def fit_link(group: LinkGeometry, config: SpherizeConfig = SpherizeConfig()) -> tuple[np.ndarray, dict]:
    """Spheres ``(S, 4)`` [x, y, z, r] covering ``group``'s surface, and what was measured (see the module
    docstring). Deterministic given ``config.seed`` and the link's index."""
    gen = np.random.default_rng([config.seed, group.index])
    # surface points, and the parts' vertices and points on their edges: the corners and rims a cover
    # misses first (area sampling almost never lands on them)
    corners = np.concatenate([np.asarray(p.mesh.vertices) for p in group.parts])
    if len(corners) > config.fit_points:
        corners = corners[np.sort(gen.choice(len(corners), config.fit_points, replace=False))]
    pts = np.concatenate(
        [group.sample(config.fit_points, gen), corners, _edge_points(group, config.fit_points // 3, gen)]
    )
    solid, pitch = _solid(group, config.voxels)
    cell = pitch**3
    if len(solid) > config.candidates:
        cand = solid[np.sort(gen.choice(len(solid), config.candidates, replace=False))]
    else:
        cand = solid
    vol_pts = solid if len(solid) <= 8000 else solid[np.sort(gen.choice(len(solid), 8000, replace=False))]
    vol_cell = cell * len(solid) / len(vol_pts)
    solid_volume = cell * len(solid)
    t = torch.from_numpy
    D = torch.cdist(t(cand), t(pts)).numpy()  # (K, N)
    Dv = torch.cdist(t(cand), t(vol_pts)).numpy()  # (K, V)
    lo = np.maximum(D.min(1), pitch)
    hi = D.max(1)
    steps = np.linspace(0.0, 1.0, config.radii)
    R = lo[:, None] * (hi / lo)[:, None] ** steps[None, :]  # (K, Rn) geometric ladder
    inside = np.stack([(Dv <= R[:, j : j + 1]).sum(1) for j in range(config.radii)], 1) * vol_cell
    excess = np.maximum(4.0 / 3.0 * math.pi * R**3 - inside, 0.0)
    cost = excess + config.sphere_price * solid_volume
    order = np.argsort(D, axis=1)
    Ds = np.take_along_axis(D, order, 1)
    count = np.stack([(Ds <= R[:, j : j + 1]).sum(1) for j in range(config.radii)], 1)  # points within
    covered = np.zeros(len(pts), dtype=bool)
    chosen: list[tuple[int, float]] = []
    while not covered.all():
        u = torch.from_numpy((~covered).astype(np.float32))
        # newly covered points per (centre, radius): the uncovered points among the first `count` sorted
        cum = torch.cumsum(u[torch.from_numpy(order)], dim=1).numpy()  # (K, N)
        gain = np.where(count > 0, np.take_along_axis(cum, np.maximum(count - 1, 0), 1), 0.0)
        score = np.where(gain > 0, gain / cost, -1.0)
        k, j = np.unravel_index(int(np.argmax(score)), score.shape)
        chosen.append((int(k), float(R[k, j])))
        covered |= D[k] <= R[k, j]
    centres = cand[[k for k, _ in chosen]]
    radii = np.array([r for _, r in chosen])
    centres, radii = _tighten(centres, radii, pts)
    # a denser, independent sample: every point ends inside, the least growth each
    check_gen = np.random.default_rng([config.seed, group.index, 1])
    check = np.concatenate(
        [
            group.sample(config.check_points, check_gen),
            corners,
            _edge_points(group, config.check_points // 3, check_gen),
        ]
    )
    grown = 0.0
    for _ in range(3):
        d = np.linalg.norm(check[:, None, :] - centres[None], axis=-1) - radii[None]
        out = d.min(1) > 0
        if not out.any():
            break
        pts = np.concatenate([pts, check[out]])
        need = np.linalg.norm(check[out][:, None, :] - centres[None], axis=-1)
        for i in range(need.shape[0]):
            s = int(np.argmin(need[i] - radii))
            grown = max(grown, float(need[i, s] - radii[s]))
            radii[s] = max(radii[s], need[i, s])
    radii = np.ceil(radii * 1e5) / 1e5
    report = {
        "link": group.name,
        "index": group.index,
        "spheres": len(radii),
        "solid_volume": solid_volume,
        "voxel_pitch": pitch,
        "largest_growth": grown,
    }
    return np.concatenate([centres, radii[:, None]], 1), report


def _edge_points(group: LinkGeometry, n: int, gen: np.random.Generator) -> np.ndarray:
    """``(n, 3)`` points on the parts' mesh edges, length-weighted."""
    segs = np.concatenate([np.asarray(p.mesh.vertices)[np.asarray(p.mesh.edges_unique)] for p in group.parts])
    length = np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1)
    if n <= 0 or length.sum() <= 0:
        return np.zeros((0, 3))
    pick = gen.choice(len(segs), size=n, p=length / length.sum())
    t = gen.random(n)[:, None]
    return segs[pick, 0] + t * (segs[pick, 1] - segs[pick, 0])


def _tighten(centres: np.ndarray, radii: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop spheres whose points all lie in others, and shrink each to the farthest point only it holds."""
    D = np.linalg.norm(pts[:, None, :] - centres[None], axis=-1)  # (N, S)
    radii = radii.copy()
    for s in np.argsort(radii):  # small first: they are the likeliest to be redundant
        inside = D <= radii[None]
        others = np.delete(inside, s, axis=1).any(1)
        own = inside[:, s] & ~others
        radii[s] = D[own, s].max() if own.any() else 0.0
    keep = radii > 0
    return centres[keep], radii[keep]


def coverage(spheres: np.ndarray, points: np.ndarray, tolerance: float = 0.002) -> dict:
    """How well spheres ``(S, 4)`` cover ``points`` ``(N, 3)`` (same frame): the share inside some
    sphere, the share more than ``tolerance`` outside every sphere, and the farthest outside (m)."""
    d = np.linalg.norm(points[:, None, :] - spheres[None, :, :3], axis=-1) - spheres[None, :, 3]
    gap = d.min(1)
    return {
        "points": len(points),
        "inside": float((gap <= 0).mean()),
        "beyond_tolerance": int((gap > tolerance).sum()),
        "farthest_outside": float(max(gap.max(), 0.0)),
    }


def srdf_disabled_links(srdf: str | Path) -> list[tuple[str, str]]:
    """The link pairs an SRDF's ``<disable_collisions>`` elements list."""
    try:
        root = ET.fromstring(Path(srdf).read_bytes())
    except (OSError, ET.ParseError) as exc:
        raise RobotDescriptionError(f"the SRDF {srdf} could not be read: {exc}") from exc
    return [(el.get("link1"), el.get("link2")) for el in root.iter("disable_collisions")]


def _always_touching(robot: Robot, spheres: np.ndarray, samples: int, seed: int) -> list[tuple[int, int]]:
    """Link pairs (two or more apart) whose spheres touch in every one of ``samples`` configurations."""
    from .body import BodySpheres

    body = BodySpheres(robot, spheres, np.zeros((0, 2), dtype=np.int64)).double()
    q = robot.sample(samples, torch.Generator().manual_seed(seed), dtype=torch.float64)
    link = spheres[:, 0].astype(np.int64)
    out = []
    with torch.no_grad():
        c = body(q)
        r = body.radii
        for a in range(robot.dof + 1):
            for b in range(a + 2, robot.dof + 1):
                ia, ib = np.flatnonzero(link == a), np.flatnonzero(link == b)
                if len(ia) == 0 or len(ib) == 0:
                    continue
                gap = torch.cdist(c[:, ia], c[:, ib]) - r[ia][:, None] - r[ib][None, :]
                if bool((gap.amin(dim=(1, 2)) < 0).all()):
                    out.append((a, b))
    return out


def spherize(
    robot: Robot,
    urdf: str | Path | None = None,
    srdf: str | Path | None = None,
    config: SpherizeConfig = SpherizeConfig(),
    package_dirs: tuple = (),
    progress=None,
) -> SphereFit:
    """Fit covering spheres to the collision geometry of ``robot``'s URDF (or of ``urdf``, with the same
    joint names), link by link, and find the link pairs a self-collision check leaves out (see the
    module docstring). ``progress(done, total)`` is called after each link."""
    groups = link_geometry(robot, urdf, package_dirs, config.sweep)
    rows, report = [], []
    todo = [g for g in groups if g.parts]
    for n, g in enumerate(todo):
        s, rep = fit_link(g, config)
        rows.append(np.concatenate([np.full((len(s), 1), float(g.index)), s], 1))
        report.append(rep)
        if progress is not None:
            progress(n + 1, len(todo))
    spheres = np.concatenate(rows)
    excluded: dict[tuple[int, int], str] = {}
    if srdf is not None:
        path = Path(urdf) if urdf is not None else robot.urdf_path
        root = ET.fromstring(path.read_bytes() if path is not None else robot.urdf)
        for a, b in srdf_disabled_links(srdf):
            ia, ib = chain_link_of(robot, root, a), chain_link_of(robot, root, b)
            if ia is not None and ib is not None and abs(ia - ib) >= 2:
                excluded[(min(ia, ib), max(ia, ib))] = "srdf"
    for pair in _always_touching(robot, spheres, config.samples, config.seed):
        excluded.setdefault(pair, "always touching")
    if config.never:  # as an SRDF generator does: pairs whose meshes never met in the sampled configurations
        mesh = MeshBody(robot, urdf, package_dirs, excluded_link_pairs=())
        q = robot.sample(config.samples, torch.Generator().manual_seed(config.seed + 1), dtype=torch.float64)
        met = mesh.touching_link_pairs(q.numpy()).any(0)
        for pair, ever in zip(mesh.pair_links, met, strict=True):
            if not ever:
                excluded.setdefault(pair, f"never touching (meshes, {config.samples} configurations)")
    pairs = sorted(excluded)
    return SphereFit(
        robot.name,
        spheres,
        [g.name for g in groups],
        pairs,
        [excluded[p] for p in pairs],
        report,
        config,
    )


def write_spherized_urdf(
    fit: SphereFit, robot: Robot, out: str | Path, urdf: str | Path | None = None
) -> Path:
    """Write ``robot``'s URDF (or ``urdf``) with its collision elements replaced by ``fit``'s spheres,
    each in the frame of its chain link, the format of the shipped spherized URDFs. Returns the path."""
    path = Path(urdf) if urdf is not None else robot.urdf_path
    root = ET.fromstring(path.read_bytes() if path is not None else robot.urdf)
    links = {el.get("name"): el for el in root.findall("link")}
    for el in links.values():
        for col in el.findall("collision"):
            el.remove(col)
    for row in fit.spheres:
        k, x, y, z, r = row
        link = links[fit.links[int(k)]]
        col = ET.SubElement(link, "collision")
        ET.SubElement(col, "origin", xyz=f"{x:.6f} {y:.6f} {z:.6f}", rpy="0 0 0")
        geom = ET.SubElement(col, "geometry")
        ET.SubElement(geom, "sphere", radius=f"{r:.5f}")
    ET.indent(root)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    text = ET.tostring(root, encoding="unicode")
    out.write_text(
        '<?xml version="1.0"?>\n'
        f"<!-- collision spheres fitted by kinlearn.collision.spherize to the collision geometry of "
        f"{path.name if path else robot.name} (seed {fit.config.seed}) -->\n{text}\n"
    )
    return out


def write_sphere_model(
    fit: SphereFit, robot: Robot, folder: str | Path, urdf: str | Path | None = None
) -> Path:
    """Write ``folder/<robot>_spherized.urdf`` and ``folder/collision_spheres.json`` (the format of
    ``robots/<robot>/``: the fitted set as its default, the excluded link pairs, how they were made).
    Returns the JSON's path, which ``register_robot(spheres=...)`` takes as well as the URDF."""
    folder = Path(folder)
    name = re.sub(r"[^A-Za-z0-9_.+-]", "_", robot.name)
    urdf_out = write_spherized_urdf(fit, robot, folder / f"{name}_spherized.urdf", urdf)
    model = {
        "robot": robot.name,
        "format": 1,
        "units": "metres",
        "frames": "Spheres are read from the URDF at load time, each in the frame of the chain link it is written on.",
        "default_set": "fitted",
        "sets": {
            "fitted": {
                "source": "fitted by kinlearn.collision.spherize to the URDF's own collision geometry",
                "urdf": urdf_out.name,
                "drop_links": [],
                "config": {k: getattr(fit.config, k) for k in fit.config.__dataclass_fields__},
                "links": fit.report,
            }
        },
        "self_collision": {
            "rule": "sphere pairs on links at least two apart, less those overlapping in at least `share` of "
            "`samples` uniformly drawn configurations (seeded), less the excluded link pairs",
            "share": 0.95,
            "samples": 2000,
            "seed": 0,
            "excluded_link_pairs": [list(p) for p in fit.excluded_link_pairs],
            "excluded_because": fit.why,
        },
    }
    out = folder / "collision_spheres.json"
    out.write_text(json.dumps(model, indent=1) + "\n")
    return out


def excess_volume(
    spheres: np.ndarray, group: LinkGeometry, voxels: int = 32, samples: int = 20000, seed: int = 0
) -> dict:
    """The volume (m³) of the union of ``spheres`` ``(S, 4)``, of the link's solid (voxelised) and of the
    union outside the solid, by Monte Carlo: points drawn uniformly in the spheres, each weighted by one
    over the number of spheres holding it."""
    gen = np.random.default_rng(seed)
    solid, pitch = _solid(group, voxels)
    cells = {tuple(k) for k in np.round(solid / pitch).astype(np.int64)}
    vol = 4.0 / 3.0 * math.pi * spheres[:, 3] ** 3
    which = gen.choice(len(spheres), size=samples, p=vol / vol.sum())
    v = gen.normal(size=(samples, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    p = spheres[which, :3] + v * (spheres[which, 3] * gen.random(samples) ** (1 / 3))[:, None]
    mult = (np.linalg.norm(p[:, None, :] - spheres[None, :, :3], axis=-1) <= spheres[None, :, 3]).sum(1)
    w = vol.sum() / samples / np.maximum(mult, 1)
    inside = np.array([tuple(k) in cells for k in np.round(p / pitch).astype(np.int64)])
    union = float(w.sum())
    return {
        "union": union,
        "solid": pitch**3 * len(solid),
        "excess": float(w[~inside].sum()),
    }
