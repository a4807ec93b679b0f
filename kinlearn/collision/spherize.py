"""Collision spheres fitted to a URDF's own collision geometry.

:func:`spherize` takes the URDF's ``<collision>`` geometry gathered per link of the robot's chain
(:func:`~kinlearn.collision.urdf_geometry.link_geometry`: link k is the child of joint k, 0 the base;
geometry behind a movable joint off the chain, a gripper's fingers, swept over that joint's range).

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
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ..body.robot import Robot
from ..errors import ConfigError, RobotDescriptionError
from .mesh import MeshBody, chain_link_of
from .urdf_geometry import LinkGeometry, _edge_points, _solid, link_geometry
from .urdf_geometry import resolve_mesh_path as resolve_mesh_path

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
