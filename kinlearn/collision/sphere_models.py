"""Where a robot's collision spheres are read from: the sphere models of the bundled ``robots/`` and
spherized URDFs.

A robot's sphere model lives in ``robots/<robot>/collision_spheres.json`` (:data:`SPHERE_FILE`; see
``robots/README.md`` for where each number comes from): named sets of spheres, each a table of rows
``[link, x, y, z, r]`` or a spherized URDF (:func:`sphere_sets` reads the file). Two sets exist for the
iiwa14, both Drake's published sphere models: the ``sparse`` set (12 spheres on links 1–7, the base
cylinder covered by 6 spheres, :func:`cover_cylinder`, 18 in all) and the ``dense`` set (46 spheres, 4 of
them on the base). A spherized URDF (one ``<collision><geometry><sphere>`` per sphere) is read into the
robot's link frames by :func:`urdf_spheres`, and the joint limits it gives by :func:`urdf_limits`. The
body these spheres make is :class:`~kinlearn.collision.body.BodySpheres`.
"""

from __future__ import annotations

import json
import math
from functools import cache
from pathlib import Path

import numpy as np

from ..body.robot import Robot, _bundled_dir
from ..errors import ConfigError, RobotDescriptionError

__all__ = ["SPHERE_FILE", "SPHERE_FORMAT", "cover_cylinder", "sphere_sets", "urdf_limits", "urdf_spheres"]

#: File name of a robot's sphere model inside its folder of the bundled ``robots/``.
SPHERE_FILE = "collision_spheres.json"
SPHERE_FORMAT = 1


def cover_cylinder(
    centre: tuple[float, float, float],
    radius: float,
    length: float,
    ring: int = 6,
    ring_radius: float = 0.054,
) -> np.ndarray:
    """Spheres ``(ring, 4)`` [x, y, z, r] that together contain a z-axis cylinder.

    One ring of ``ring`` equal spheres in the cylinder's mid-plane, centres ``ring_radius`` from its
    axis. Each sphere contains the full-height column over a disc of radius
    c = sqrt(R² + d² − 2 R d cos(π/ring)) around its centre (R the cylinder's radius, d the ring
    radius): neighbouring discs then meet on the cylinder's rim, and for d ≤ R / (2 cos(π/ring)) the
    ring also covers the axis. The sphere radius is sqrt(c² + (length/2)²), rounded up to 1e-5 m.
    """
    R, d, h = float(radius), float(ring_radius), float(length) / 2.0
    half = math.pi / ring
    if not (ring >= 3 and 0.0 < d <= R / (2.0 * math.cos(half))):
        raise ConfigError(
            f"a ring of {ring} spheres at {d} m from the axis cannot cover a cylinder of radius {R} m; "
            f"use ring >= 3 and 0 < ring_radius <= {R / (2.0 * math.cos(half)):.4g}"
        )
    c = math.sqrt(R * R + d * d - 2.0 * R * d * math.cos(half))
    rho = math.ceil(math.sqrt(c * c + h * h) * 1e5) / 1e5
    k = np.arange(ring)
    out = np.empty((ring, 4))
    out[:, 0] = centre[0] + d * np.cos(2 * half * k)
    out[:, 1] = centre[1] + d * np.sin(2 * half * k)
    out[:, 2] = centre[2]
    out[:, 3] = rho
    return out


@cache
def _read_model(path: str) -> dict:
    return json.loads(Path(path).read_text())


def _model_path(robot: Robot) -> Path:
    return _bundled_dir() / robot.name / SPHERE_FILE


def sphere_sets(robot: Robot) -> dict:
    """The raw sphere model of ``robot`` as read from its JSON file (see ``robots/README.md``)."""
    path = _model_path(robot)
    if not path.is_file():
        raise RobotDescriptionError(
            f"robot {robot.name!r} has no collision sphere model (no {SPHERE_FILE} in its folder of "
            f"kinlearn's robots/); sphere bodies exist for: {', '.join(_robots_with_spheres())}"
        )
    model = _read_model(str(path))
    if model.get("format") != SPHERE_FORMAT or model.get("robot") != robot.name:
        raise RobotDescriptionError(
            f"{path} is not a format-{SPHERE_FORMAT} sphere model of {robot.name!r} "
            f"(format {model.get('format')!r}, robot {model.get('robot')!r})"
        )
    return model


def _robots_with_spheres() -> list[str]:
    root = _bundled_dir()
    return sorted(p.parent.name for p in root.glob(f"*/{SPHERE_FILE}"))


def urdf_spheres(robot: Robot, urdf: str | Path | bytes, drop_links: tuple[str, ...] = ()) -> np.ndarray:
    """The collision spheres of a spherized URDF (one ``<collision><geometry><sphere>`` per sphere) as rows
    ``[link, x, y, z, r]`` in ``robot``'s link frames, sorted by link (base, 0, first).

    Each sphere's link is walked up the URDF's fixed joints to the nearest link that a joint of
    ``robot`` moves (matched by joint name; the sphere is folded onto it, its centre carried through
    the fixed joints' origins), or to the parent of the robot's first joint (the base, 0, expressed in
    the robot's root frame). Spheres on links in ``drop_links``, or folded through one, are left out
    (parts the robot's own description does not have: a gripper, a sensor), and so are spheres above the
    base (a stand). A sphere behind a moving joint that ``robot`` lacks is a
    :class:`~kinlearn.errors.RobotDescriptionError` naming it.
    """

    from ..body.robot import _origin, validate_urdf

    data = urdf if isinstance(urdf, bytes) else Path(urdf).read_bytes()
    root = validate_urdf(data, "the sphere URDF")  # a tree of declared, uniquely named links and joints
    by_child = {}
    for el in root.iter("joint"):
        child, parent = el.find("child"), el.find("parent")
        if child is None or parent is None:
            continue
        by_child[child.get("link")] = (
            el.get("name"),
            el.get("type"),
            parent.get("link"),
            _origin(el.find("origin"), f"joint {el.get('name')}"),
        )
    index = {j.name: k + 1 for k, j in enumerate(robot.joints)}
    first = next((c for c, (n, *_rest) in by_child.items() if n == robot.joints[0].name), None)
    if first is None:
        raise RobotDescriptionError(
            f"the sphere URDF has no joint {robot.joints[0].name!r}, {robot.name}'s first joint"
        )
    base_link, origin1 = by_child[first][2], by_child[first][3]
    to_root = robot.joints[0].T_prev @ np.linalg.inv(origin1)  # the base link's frame in the robot's root
    rows = []
    for link in root.iter("link"):
        name = link.get("name")
        for col in link.findall("collision"):
            sphere = col.find("geometry/sphere")
            if sphere is None:
                continue
            try:
                r = float(sphere.get("radius"))
            except (TypeError, ValueError):
                r = math.nan
            if not (math.isfinite(r) and r > 0):
                raise RobotDescriptionError(
                    f"a collision sphere of link {name!r} has radius {sphere.get('radius')!r}; a radius is a "
                    "finite number of metres > 0"
                )
            T = _origin(col.find("origin"), f"a collision sphere of {name}")
            cur, k = name, None
            while True:
                if cur in drop_links:
                    break
                if cur == base_link:
                    T, k = to_root @ T, 0
                    break
                if cur not in by_child:
                    break  # above the base: not part of the robot
                jname, jtype, parent, origin = by_child[cur]
                if jname in index:
                    k = index[jname]
                    break
                if jtype != "fixed":
                    raise RobotDescriptionError(
                        f"a collision sphere of link {name!r} sits behind joint {jname!r} ({jtype}), which "
                        f"{robot.name} does not have; drop the link or fix the joint"
                    )
                T, cur = origin @ T, parent
            if k is not None:
                rows.append([k, *T[:3, 3], r])
    if not rows:
        raise RobotDescriptionError(f"the sphere URDF holds no collision sphere on {robot.name}'s links")
    out = np.asarray(rows, dtype=np.float64)
    return out[np.argsort(out[:, 0], kind="stable")]


def urdf_limits(robot: Robot, urdf: str | Path | bytes) -> tuple[np.ndarray, np.ndarray]:
    """The position limits a sphere URDF gives ``robot``'s joints (matched by name): ``(lower, upper)``,
    float64 ``(dof,)``. A joint the file lacks, or gives no limit, keeps the robot's. (The ur5's file, the
    standard benchmarks' UR5, limits every joint to ±π, where kinlearn's ur5 turns ±2π; the panda's, MoveIt's
    panda, is up to 0.07 rad wider than the Franka datasheet's limits of kinlearn's panda.)"""
    from ..body.robot import validate_urdf

    data = urdf if isinstance(urdf, bytes) else Path(urdf).read_bytes()
    root = validate_urdf(data, "the sphere URDF")
    given = {}
    for el in root.iter("joint"):
        lim = el.find("limit")
        if el.get("type") in ("revolute", "prismatic") and lim is not None:
            try:
                given[el.get("name")] = (float(lim.get("lower")), float(lim.get("upper")))
            except (TypeError, ValueError) as exc:
                raise RobotDescriptionError(
                    f"joint {el.get('name')!r} of the sphere URDF has an unreadable limit"
                ) from exc
    lo, hi = robot.lower.astype(np.float64).copy(), robot.upper.astype(np.float64).copy()
    for k, j in enumerate(robot.joints):
        if j.name in given:
            lo[k], hi[k] = given[j.name]
    return lo, hi
