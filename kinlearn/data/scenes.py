"""Procedural obstacle scenes: families of the structures users plan among, scaled to an arm's reach.

Each family builds one scene of typed primitives (:mod:`kinlearn.collision.geometry`: boxes in any
orientation, cylinders, spheres; a floor at z = 0) and two samplers of end-effector targets, one for
the start and one for the goal, placed where the family makes planning hard: inside cells, under
tables, behind walls, with obstacles across the straight path between them. Sizes are written for an
arm of the iiwa14's horizontal reach and multiplied by the arm's :func:`scene_scale` (board and bar
thicknesses stay as they are). Every scene is finally turned about the base's z axis by a random yaw,
so that the same structure appears on every side of the robot and its boxes are rotated in the base
frame (in one published benchmark 98% of the boxes are).

=============  ====================================================================================
``bookcase``   a bookcase of 2–4 levels and 1–3 columns, open towards the robot; the goal inside a
               cell, the start in another cell or in front of the shelf.
``cubby``      one or two open-front boxes at a random height; the goal inside one, the start inside
               the other or outside above or beside it.
``cage``       a frame of posts and rails (cylinders) with a top, a back and barred sides; the goal
               inside, the start outside.
``bin``        one or two open-top boxes on the floor or raised; the goal low inside one, the start
               inside the other or above the rim outside.
``table``      a table on four legs with 2–6 objects (rotated boxes, upright cylinders, spheres) on it;
               start and goal behind different objects, or one under the table.
``wall``       a wall between start and goal, sometimes with a window, turned off square to the arm.
``clutter``    4–12 primitives of every kind in any orientation anywhere in reach, 1–3 of them across
               the straight segment between the start and goal targets.
=============  ====================================================================================

:func:`build_scene` returns one :class:`SceneLayout`; the problem generator
(:mod:`kinlearn.data.problems`) turns its targets into joint configurations by IK and keeps the valid
ones. Everything is drawn from the ``torch.Generator`` passed in, so one seed gives one scene.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import torch

from ..body.kinematics import kinematics
from ..body.robot import Robot
from ..checks import as_real
from ..collision.geometry import Box, Cylinder, Primitive, Sphere
from ..collision.scene import Scene
from ..errors import ConfigError

__all__ = ["SCENE_FAMILIES", "SceneLayout", "build_scene", "scene_scale", "yaw_matrix"]

_F64 = torch.float64
#: Horizontal reach of the iiwa14 (m, the largest |p_xy| over its joint range), the unit of the families.
IIWA14_HORIZONTAL_REACH = 0.944
#: Thickness of boards (m), kept whatever the arm's size.
BOARD = 0.02
#: How far (m) an end-effector target is drawn from every obstacle (the hand around it needs room).
TARGET_CLEARANCE = 0.03

#: A sampler of end-effector targets: (count, generator) → (count, 3), base frame.
Sampler = Callable[[int, torch.Generator], torch.Tensor]


@dataclass(frozen=True)
class SceneLayout:
    """One generated scene: its primitives (base frame, floor at z = 0 implied), where start and goal
    targets are drawn, and the family that made it."""

    family: str
    primitives: tuple[Primitive, ...]
    start: Sampler
    goal: Sampler
    #: The way a hand holding a grasp in the family's cells points (unit, base frame): into a
    #: bookcase's, a cubby's or a cage's cells, down into a bin; None for the open families.
    approach: np.ndarray | None = None

    def scene(self, dtype: torch.dtype = _F64) -> Scene:
        """The obstacles as a :class:`~kinlearn.collision.Scene` with the floor at z = 0."""
        return Scene.from_primitives(self.primitives, floor=0.0, dtype=dtype)


# --------------------------------------------------------------------------------------------------
# Drawing numbers
# --------------------------------------------------------------------------------------------------


def _u(g: torch.Generator, lo, hi, n: int | None = None):
    """A number uniform in [lo, hi) (a float), or ``n`` of them (a float64 tensor)."""
    if n is None:
        return lo + (hi - lo) * float(torch.rand((), generator=g, dtype=_F64))
    return lo + (hi - lo) * torch.rand(n, generator=g, dtype=_F64)


def _randint(g: torch.Generator, lo: int, hi: int) -> int:
    """An integer in [lo, hi]."""
    return int(torch.randint(lo, hi + 1, (), generator=g))


def _chance(g: torch.Generator, p: float) -> bool:
    return float(torch.rand((), generator=g)) < p


def yaw_matrix(yaw: float) -> np.ndarray:
    """The rotation by ``yaw`` radians about z."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _random_rotation(g: torch.Generator) -> np.ndarray:
    """A rotation drawn uniformly (a normalised Gaussian quaternion)."""
    w, x, y, z = (torch.randn(4, generator=g, dtype=_F64) / 1.0).tolist()
    n = math.sqrt(w * w + x * x + y * y + z * z) or 1.0
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _box(centre, half, R: np.ndarray | None = None) -> Box:
    return Box(tuple(centre), tuple(half), tuple(np.eye(3).ravel() if R is None else R.ravel()))


def _post(centre, radius: float, half_length: float, R: np.ndarray | None = None) -> Cylinder:
    return Cylinder(tuple(centre), radius, half_length, tuple(np.eye(3).ravel() if R is None else R.ravel()))


def _region(lo, hi) -> Sampler:
    """Targets uniform in the axis-aligned box [lo, hi] (of the family's own frame)."""
    lo_t, hi_t = torch.tensor(lo, dtype=_F64), torch.tensor(hi, dtype=_F64)

    def sample(n: int, g: torch.Generator) -> torch.Tensor:
        return lo_t + (hi_t - lo_t) * torch.rand(n, 3, generator=g, dtype=_F64)

    return sample


# --------------------------------------------------------------------------------------------------
# Families, in the frame of a structure that faces the robot along +x, for an arm of scale s
# --------------------------------------------------------------------------------------------------


def _open_box(x_open, yc, z0, depth, half_w, height, open_face: str) -> list[Primitive]:
    """A box of boards open on one face ("front": towards the robot, "top"): back/sides/top/bottom."""
    t = BOARD
    xc, zc = x_open + depth / 2, z0 + height / 2
    out = [
        _box((xc, yc - half_w + t / 2, zc), (depth / 2, t / 2, height / 2)),  # sides
        _box((xc, yc + half_w - t / 2, zc), (depth / 2, t / 2, height / 2)),
        _box((xc, yc, z0 + t / 2), (depth / 2, half_w, t / 2)),  # bottom
    ]
    if open_face == "front":
        out.append(_box((x_open + depth - t / 2, yc, zc), (t / 2, half_w, height / 2)))  # back
        out.append(_box((xc, yc, z0 + height - t / 2), (depth / 2, half_w, t / 2)))  # top
    else:  # open at the top: front and back walls
        out.append(_box((x_open + t / 2, yc, zc), (t / 2, half_w, height / 2)))
        out.append(_box((x_open + depth - t / 2, yc, zc), (t / 2, half_w, height / 2)))
    return out


def _bookcase(g, s, _tool):
    x_open, depth = s * _u(g, 0.5, 0.7), s * _u(g, 0.3, 0.4)
    columns, levels = _randint(g, 1, 3), _randint(g, 2, 4)
    col_w = s * _u(g, 0.3, 0.45) if columns > 1 else s * _u(g, 0.5, 0.8)
    level_h = s * _u(g, 0.28, 0.4)
    half_w, height = columns * col_w / 2, levels * level_h
    yc, bottom = s * _u(g, -0.15, 0.15), s * _u(g, 0.0, 0.35)
    if bottom + height > 1.45 * s:  # keep the top level within reach
        levels -= 1
        height = levels * level_h
    t, xc = BOARD, x_open + depth / 2
    prims = _open_box(x_open, yc, bottom, depth, half_w, height, "front")
    prims += [_box((xc, yc, bottom + k * level_h), (depth / 2, half_w, t / 2)) for k in range(1, levels)]
    prims += [
        _box((xc, yc - half_w + k * col_w, bottom + height / 2), (depth / 2, t / 2, height / 2))
        for k in range(1, columns)
    ]
    m = 0.09 * s  # a target this far from a cell's boards

    def cell(k, c):
        y0 = yc - half_w + c * col_w
        return _region(
            (x_open + 0.04 * s, y0 + m, bottom + k * level_h + m),
            (x_open + 0.16 * s, y0 + col_w - m, bottom + (k + 1) * level_h - m),
        )

    cells = [(k, c) for k in range(levels) for c in range(columns)]
    goal = cells[_randint(g, 0, len(cells) - 1)]
    others = [c for c in cells if c != goal]
    if _chance(g, 0.7):
        start = cell(*others[_randint(g, 0, len(others) - 1)])
    else:
        start = _region(
            (x_open - 0.3 * s, yc - half_w, bottom + 0.1 * s),
            (x_open - 0.12 * s, yc + half_w, bottom + height),
        )
    return prims, start, cell(*goal)


def _one_or_two(g, s, half_w, p_two: float, max_gap: float) -> tuple[bool, list[float]]:
    """Whether a box comes as a pair (chance ``p_two``), and the y of each box's centre: one near the
    middle, or two side by side with a gap of 5 cm to ``max_gap`` (× ``s``) between them."""
    two = _chance(g, p_two)
    gap = s * _u(g, 0.05, max_gap)
    centre = s * _u(g, -0.1, 0.1)
    if two:
        return True, [centre - half_w - gap / 2, centre + half_w + gap / 2]
    return False, [centre]


def _cubby(g, s, _tool):
    depth, half_w, height = s * _u(g, 0.25, 0.35), s * _u(g, 0.13, 0.2), s * _u(g, 0.24, 0.36)
    x_open, z0 = s * _u(g, 0.4, 0.6), s * _u(g, 0.0, 0.7)
    two, centres = _one_or_two(g, s, half_w, 0.5, 0.15)
    prims = [p for yc in centres for p in _open_box(x_open, yc, z0, depth, half_w, height, "front")]
    m = 0.08 * s

    def inside(yc):
        return _region(
            (x_open + 0.03 * s, yc - half_w + m, z0 + m),
            (x_open + 0.14 * s, yc + half_w - m, z0 + height - m),
        )

    k = _randint(g, 0, len(centres) - 1)
    if two and _chance(g, 0.6):
        start = inside(centres[1 - k])
    elif _chance(g, 0.5):  # above the cubby
        start = _region(
            (x_open, centres[0] - half_w, z0 + height + 0.1 * s),
            (x_open + depth, centres[-1] + half_w, z0 + height + 0.3 * s),
        )
    else:  # beside it
        if _chance(g, 0.5):
            y_lo, y_hi = centres[-1] + half_w + 0.1 * s, centres[-1] + half_w + 0.22 * s
        else:
            y_lo, y_hi = centres[0] - half_w - 0.22 * s, centres[0] - half_w - 0.1 * s
        start = _region((x_open, y_lo, z0), (x_open + depth, y_hi, z0 + height))
    return prims, start, inside(centres[k])


def _cage(g, s, _tool):
    depth, half_w, height = s * _u(g, 0.3, 0.45), s * _u(g, 0.2, 0.35), s * _u(g, 0.3, 0.5)
    x_open, z0, yc = s * _u(g, 0.4, 0.6), s * _u(g, 0.0, 0.4), s * _u(g, -0.15, 0.15)
    r = _u(g, 0.008, 0.015)
    x1 = x_open + depth
    zc = z0 + height / 2
    prims: list[Primitive] = [
        _post((x, y, zc), r, height / 2) for x in (x_open, x1) for y in (yc - half_w, yc + half_w)
    ]
    along_x, along_y = (
        np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]]),
        np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]),
    )
    top = z0 + height
    prims += [_post((x_open + depth / 2, y, top), r, depth / 2, along_x) for y in (yc - half_w, yc + half_w)]
    prims += [_post((x, yc, top), r, half_w, along_y) for x in (x_open, x1)]
    prims.append(_box((x_open + depth / 2, yc, top + BOARD / 2), (depth / 2, half_w, BOARD / 2)))  # top
    prims.append(_box((x1 + BOARD / 2, yc, zc), (BOARD / 2, half_w, height / 2)))  # back
    spacing = s * _u(g, 0.07, 0.12)
    n_bars = max(1, int(depth / spacing))
    for k in range(1, n_bars):
        x = x_open + k * depth / n_bars
        prims += [_post((x, y, zc), r, height / 2) for y in (yc - half_w, yc + half_w)]
    m = 0.09 * s
    goal = _region(
        (x_open + 0.04 * s, yc - half_w + m, z0 + m), (x_open + 0.15 * s, yc + half_w - m, top - m)
    )
    if _chance(g, 0.5):  # above the cage
        start = _region((x_open, yc - half_w, top + 0.12 * s), (x1, yc + half_w, top + 0.3 * s))
    else:
        side = 1.0 if _chance(g, 0.5) else -1.0
        y_lo, y_hi = sorted((yc + side * (half_w + 0.12 * s), yc + side * (half_w + 0.3 * s)))
        start = _region((x_open, y_lo, z0 + 0.05 * s), (x1, y_hi, top))
    return prims, start, goal


def _bin(g, s, tool):
    depth, half_w, height = s * _u(g, 0.3, 0.45), s * _u(g, 0.15, 0.25), s * _u(g, 0.15, 0.3)
    x_open, z0 = s * _u(g, 0.4, 0.6), s * _u(g, 0.0, 0.35)
    two, centres = _one_or_two(g, s, half_w, 0.6, 0.25)
    prims = [p for yc in centres for p in _open_box(x_open, yc, z0, depth, half_w, height, "top")]
    m = 0.08 * s

    def inside(yc):  # the end effector low in the bin; a tool's length higher, so the tool is low in it
        return _region(
            (x_open + m, yc - half_w + m, z0 + 0.06 * s + tool),
            (x_open + depth - m, yc + half_w - m, z0 + height * 0.8 + tool),
        )

    k = _randint(g, 0, len(centres) - 1)
    if two and _chance(g, 0.7):
        start = inside(centres[1 - k])
    else:
        start = _region(
            (x_open - 0.25 * s, centres[0] - half_w, z0 + height + 0.08 * s),
            (x_open - 0.05 * s, centres[-1] + half_w, z0 + height + 0.35 * s),
        )
    return prims, start, inside(centres[k])


def _table(g, s, _tool):
    top, x0 = s * _u(g, 0.25, 0.5), s * _u(g, 0.3, 0.45)
    depth, half_w, yc = s * _u(g, 0.5, 0.75), s * _u(g, 0.4, 0.7), s * _u(g, -0.15, 0.15)
    t, leg = 0.03, _u(g, 0.02, 0.035)
    prims: list[Primitive] = [_box((x0 + depth / 2, yc, top - t / 2), (depth / 2, half_w, t / 2))]
    legs_h = (top - t) / 2
    for x in (x0 + 0.05 * s, x0 + depth - 0.05 * s):
        for y in (yc - half_w + 0.05 * s, yc + half_w - 0.05 * s):
            prims.append(_post((x, y, legs_h), leg, legs_h))
    objects = []  # (x, y, footprint, height)
    for _ in range(_randint(g, 2, 6)):
        for _try in range(20):
            x, y = (
                _u(g, x0 + 0.08 * s, x0 + depth - 0.08 * s),
                _u(g, yc - half_w + 0.08 * s, yc + half_w - 0.08 * s),
            )
            if all(math.hypot(x - ox, y - oy) > fr + 0.12 * s for ox, oy, fr, _ in objects):
                break
        else:
            continue
        kind = _randint(g, 0, 2)
        if kind == 0:
            hx, hy, hz = s * _u(g, 0.02, 0.07), s * _u(g, 0.02, 0.07), s * _u(g, 0.05, 0.2)
            prims.append(_box((x, y, top + hz), (hx, hy, hz), yaw_matrix(_u(g, -math.pi, math.pi))))
            objects.append((x, y, math.hypot(hx, hy), top + 2 * hz))
        elif kind == 1:
            rad, hz = s * _u(g, 0.02, 0.06), s * _u(g, 0.05, 0.18)
            prims.append(_post((x, y, top + hz), rad, hz))
            objects.append((x, y, rad, top + 2 * hz))
        else:
            rad = s * _u(g, 0.03, 0.08)
            prims.append(Sphere((x, y, top + rad), rad))
            objects.append((x, y, rad, top + 2 * rad))
    under = _region(
        (x0 + 0.12 * s, yc - half_w + 0.15 * s, 0.12 * s),
        (x0 + 0.3 * s, yc + half_w - 0.15 * s, top - 0.12 * s),
    )
    if len(objects) < 2 or _chance(g, 0.3):
        above = _region(
            (x0 + 0.1 * s, yc - half_w + 0.1 * s, top + 0.06 * s),
            (x0 + depth - 0.1 * s, yc + half_w - 0.1 * s, top + 0.3 * s),
        )
        return (prims, under, above) if _chance(g, 0.5) else (prims, above, under)
    a = _randint(g, 0, len(objects) - 1)
    b = (a + _randint(g, 1, len(objects) - 1)) % len(objects)

    def behind(k, other):
        x, y, fr, h = objects[k]
        away = math.atan2(y - objects[other][1], x - objects[other][0])

        def sample(n, gen):
            ang = away + _u(gen, -math.pi / 3, math.pi / 3, n)
            off = fr + _u(gen, 0.07 * s, 0.14 * s, n)
            z = top + 0.05 * s + (h - top) * torch.rand(n, generator=gen, dtype=_F64)
            return torch.stack([x + off * torch.cos(ang), y + off * torch.sin(ang), z], dim=1)

        return sample

    return prims, behind(a, b), behind(b, a)


def _wall(g, s, _tool):
    xc, half_len, thick = s * _u(g, 0.45, 0.65), s * _u(g, 0.25, 0.5), _u(g, 0.01, 0.04)
    height = s * _u(g, 0.4, 0.95)
    turn = yaw_matrix(_u(g, -0.5, 0.5))  # the wall off square to the arm
    c = np.array([xc, 0.0, 0.0])

    def place(local_centre, half):
        return _box(c + turn @ np.asarray(local_centre), half, turn)

    if _chance(g, 0.4):  # a window: pieces before, after, below and above an opening
        w_lo, w_hi = s * _u(g, 0.15, 0.3), s * _u(g, 0.4, 0.6)
        w_half = min(s * _u(g, 0.08, 0.15), half_len / 2)
        height = max(height, w_hi + 0.1 * s)
        side = (half_len - w_half) / 2
        prims = [
            place((-(w_half + side), 0.0, height / 2), (side, thick / 2, height / 2)),
            place((w_half + side, 0.0, height / 2), (side, thick / 2, height / 2)),
            place((0.0, 0.0, w_lo / 2), (w_half, thick / 2, w_lo / 2)),
            place((0.0, 0.0, (w_hi + height) / 2), (w_half, thick / 2, (height - w_hi) / 2)),
        ]
    else:
        prims = [place((0.0, 0.0, height / 2), (half_len, thick / 2, height / 2))]

    def beside(sign):
        """Targets on one side of the wall (which runs along its local x, radially from the arm)."""

        def sample(n, gen):
            local = torch.stack(
                [
                    _u(gen, -half_len + 0.05 * s, half_len - 0.05 * s, n),
                    sign * (thick / 2 + _u(gen, 0.12 * s, 0.3 * s, n)),
                    _u(gen, 0.1 * s, max(0.15 * s, height - 0.05 * s), n),
                ],
                dim=1,
            )
            return torch.as_tensor(c) + local @ torch.as_tensor(turn).T

        return sample

    side = 1.0 if _chance(g, 0.5) else -1.0
    return prims, beside(side), beside(-side)


def _clutter(g, s, _tool):
    def target():
        rad, ang, z = s * _u(g, 0.35, 0.85), _u(g, -1.3, 1.3), s * _u(g, 0.1, 1.0)
        return np.array([rad * math.cos(ang), rad * math.sin(ang), z])

    a, b = target(), target()
    if np.linalg.norm(a - b) < 0.35 * s:
        return None
    prims: list[Primitive] = []

    def add(centre, size):
        kind = _randint(g, 0, 2)
        R = _random_rotation(g)
        if kind == 0:
            prims.append(_box(centre, tuple(size * _u(g, 0.4, 1.0) for _ in range(3)), R))
        elif kind == 1:
            prims.append(_post(centre, size * _u(g, 0.3, 0.8), size * _u(g, 0.6, 1.5), R))
        else:
            prims.append(Sphere(tuple(centre), size))

    for _ in range(_randint(g, 1, 3)):  # across the straight segment
        f = _u(g, 0.3, 0.7)
        p = a + f * (b - a) + np.array([_u(g, -0.05, 0.05) * s for _ in range(3)])
        room = min(np.linalg.norm(p - a), np.linalg.norm(p - b)) - 0.12 * s
        if room > 0.04 * s:
            add(p, min(room, s * _u(g, 0.05, 0.15)))
    for _ in range(_randint(g, 3, 9)):
        p = target()
        room = min(np.linalg.norm(p - a), np.linalg.norm(p - b)) - 0.12 * s
        if room > 0.04 * s:
            add(p, min(room, s * _u(g, 0.04, 0.15)))
    if not prims:
        return None

    def near(p):
        def sample(n, gen):
            return torch.as_tensor(p) + 0.03 * s * torch.randn(n, 3, generator=gen, dtype=_F64)

        return sample

    return prims, near(a), near(b)


_BUILDERS: dict[str, Callable] = {
    "bookcase": _bookcase,
    "cubby": _cubby,
    "cage": _cage,
    "bin": _bin,
    "table": _table,
    "wall": _wall,
    "clutter": _clutter,
}
#: The families, in the order problem sets number them.
SCENE_FAMILIES: tuple[str, ...] = tuple(_BUILDERS)


# --------------------------------------------------------------------------------------------------
# Public entry points
# --------------------------------------------------------------------------------------------------


@lru_cache(maxsize=32)
def _horizontal_reach(robot_name: str, robot: Robot) -> float:
    q = robot.sample(20_000, torch.Generator().manual_seed(0), dtype=_F64)
    p = kinematics(robot, "fast").position(q, validate=False)
    return float(p[:, :2].norm(dim=-1).max())


def scene_scale(robot: Robot) -> float:
    """How much larger than the iiwa14's (0.944 m) the arm's horizontal reach is: the factor every
    family's positions and sizes are multiplied by (the panda's and the ur5's, with their tools, are within 1% of it)."""
    return _horizontal_reach(robot.name, robot) / IIWA14_HORIZONTAL_REACH


def _turned(p: Primitive, R: np.ndarray) -> Primitive:
    centre = R @ np.asarray(p.centre)
    if isinstance(p, Sphere):
        return Sphere(tuple(centre), p.radius)
    rot = R @ np.asarray(p.rotation).reshape(3, 3)
    if isinstance(p, Box):
        return _box(centre, p.half_extents, rot)
    return _post(centre, p.radius, p.half_length, rot)


#: The way a hand reaching into each family's cells points, before the scene's yaw (every cell opens
#: toward the robot, −x; a bin opens up).
_APPROACH: dict[str, tuple[float, float, float]] = {
    "bookcase": (1.0, 0.0, 0.0),
    "cubby": (1.0, 0.0, 0.0),
    "cage": (1.0, 0.0, 0.0),
    "bin": (0.0, 0.0, -1.0),
}


def build_scene(
    family: str,
    gen: torch.Generator,
    scale: float = 1.0,
    yaw: float | None = None,
    tries: int = 20,
    tool: float = 0.0,
) -> SceneLayout:
    """One scene of ``family`` (one of :data:`SCENE_FAMILIES`) drawn from ``gen``, sized by ``scale``
    (:func:`scene_scale` of the arm) and turned about z by ``yaw`` (default: drawn in [−π, π)).

    ``tool``: how much further (m) than the bare arm the body reaches past the end effector (a gripper
    on the flange). The bin's targets inside a bin are raised by it, so that the tool, not the flange,
    is low in the bin; no other family's targets change, and ``tool = 0`` draws the same scenes."""
    if family not in _BUILDERS:
        raise ConfigError(f"unknown scene family {family!r}; choose one of {', '.join(SCENE_FAMILIES)}")
    scale = as_real(scale, "scale", minimum=0.0, open_minimum=True, expected="a finite number > 0")
    tool = as_real(tool, "tool", minimum=0.0, expected="a finite number >= 0 (m)")
    for _ in range(tries):
        built = _BUILDERS[family](gen, float(scale), float(tool))
        if built is not None:
            break
    else:
        raise ConfigError(f"no {family} scene in {tries} draws")
    prims, start, goal = built
    angle = _u(gen, -math.pi, math.pi) if yaw is None else float(yaw)
    R = yaw_matrix(angle)
    Rt = torch.as_tensor(R.T)

    rows = [(type(p), torch.tensor(p.row(), dtype=_F64)) for p in prims]
    reach = 0.92 * IIWA14_HORIZONTAL_REACH * float(scale)

    def clear(sampler: Sampler) -> Sampler:
        """Targets at least ``TARGET_CLEARANCE`` from every obstacle and within 92% of the arm's
        horizontal reach, turned with the scene: points that break either are drawn again (a few
        rounds; the IK that turns targets into joints drops any left over)."""

        def sample(n: int, g: torch.Generator) -> torch.Tensor:
            out = sampler(n, g)
            for _ in range(8):
                d = torch.stack([kind.point_distance(out, row) for kind, row in rows]).min(0).values
                near = (d < TARGET_CLEARANCE) | (out[:, :2].norm(dim=-1) > reach)
                if not bool(near.any()):
                    break
                out[near] = sampler(int(near.sum()), g)
            return out @ Rt

        return sample

    approach = None if family not in _APPROACH else R @ np.asarray(_APPROACH[family], dtype=np.float64)
    return SceneLayout(family, tuple(_turned(p, R) for p in prims), clear(start), clear(goal), approach)
