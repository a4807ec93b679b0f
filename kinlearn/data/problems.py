"""Obstacle planning problems for any arm with a sphere body: (start joints, goal joints, scene),
verified solvable.

Ten scene families (robot base at the origin, z up, a floor at z = 0 in every scene): the seven of
:mod:`kinlearn.data.scenes` (``bookcase``, ``cubby``, ``cage``, ``bin``, ``table``, ``wall``,
``clutter``: boxes in any orientation, cylinders and spheres, sized to the arm by
:func:`~kinlearn.data.scenes.scene_scale` and turned to any yaw), and the first three, modelled on the
MπNets / MotionBenchMaker ones, written for the iiwa14's reach (the shipped iiwa14 obstacle network's
training scenes; the panda's and the ur5's horizontal reach is within 1% of it, and another arm's
scenes and targets are multiplied by its scale, rounded to 0.01, as the seven families' are):

=============  ====================================================================================
``tabletop``   a table (a 4 cm slab, top at 0–25 cm) in front of the robot with 2–6 boxes (up to 40 cm
               tall) and spheres standing on it; start and goal end effectors behind two different
               objects as seen from each other, no higher than 5 cm above them.
``shelf``      a shelf unit of 2–3 levels (back, sides, top, bottom and level boards, optionally a
               vertical divider: up to 8 boxes) 0.5–0.75 m from the base, open towards it; the goal end
               effector inside a compartment, the start in another compartment or in front of the shelf.
``barrier``    a wall 0.35–0.8 m high between the start and goal end effectors (a thin box across
               the robot's front), so the arm must go over or around it.
=============  ====================================================================================

Each of these three is turned by 0°, 90° or −90° about z (which keeps boxes axis-aligned). Start and goal are
joint configurations found by damped-least-squares IK from random initial joints towards sampled
end-effector targets, kept only if they are within the joint limits by ``joint_margin``, at least
``min_clearance`` from the scene and from self-collision, and their end effectors are ≥ 0.2 m apart.
With ``hand="grasp"`` (:class:`ProblemConfig`) the IK also turns the hand's approach axis (the last
joint's, :func:`~kinlearn.body.kinematics.approach_axis`) within :data:`GRASP_TOLERANCE` of the way into
the family's cells, as a gripper holding something there points (horizontal into a bookcase's, a
cubby's or a cage's cell, down into a bin; the other families as ``"free"``).
A problem is kept only if OMPL's RRT-Connect finds a path within ``time_limit`` seconds on the same
checker (:class:`~kinlearn.collision.ompl.RrtChecker`: a state is valid when its body–scene clearance and self-clearance are
> 0; a motion is valid when the dense check of :func:`~kinlearn.collision.check_path` finds it free,
≤ 1 cm of sphere travel between checked configurations). ``hard`` marks problems whose straight
joint-space line from start to goal collides.

Everything is seeded: problem i of ``make_problems(family, n, seed)`` uses its own sub-seed
(:func:`problem_seed`), so a set does not depend on how many attempts earlier problems needed. Only
RRT-Connect's time limit is wall-clock: a problem near the limit may be kept on one machine and
replaced on another.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from ..body.kinematics import approach_axis, dls_step, kinematics, pointing_dls_step
from ..body.robot import Robot, load_robot
from ..checks import as_real
from ..collision.body import BodySpheres, body_spheres, planning_body
from ..collision.check import check_path, clearances
from ..collision.ompl import OmplRrtConnect, import_ompl
from ..collision.scene import Scene
from ..errors import ConfigError, DatasetError, ObstacleError, PlanningError
from ..io import load_npz, save_npz
from .scenes import SCENE_FAMILIES, _randint, _u, build_scene, scene_scale

__all__ = [
    "FAMILIES",
    "FAMILY_GROUPS",
    "GRASP_TOLERANCE",
    "HANDS",
    "LEGACY_FAMILIES",
    "PROBLEM_FORMAT",
    "ProblemConfig",
    "ProblemSet",
    "make_problems",
    "problem_seed",
    "select_families",
]

#: The iiwa14's first three families (the shipped obstacle network's training scenes), then the seven
#: of :mod:`kinlearn.data.scenes` (rotated boxes, cylinders; scaled to the arm).
LEGACY_FAMILIES: tuple[str, ...] = ("tabletop", "shelf", "barrier")
FAMILIES: tuple[str, ...] = LEGACY_FAMILIES + SCENE_FAMILIES
#: Names that stand for several families where families are chosen (training, benchmark sets).
FAMILY_GROUPS: dict[str, tuple[str, ...]] = {
    "legacy": LEGACY_FAMILIES,
    "scenes": SCENE_FAMILIES,
    "all": FAMILIES,
}
#: How a problem's hand may be held at its targets (:attr:`ProblemConfig.hand`).
HANDS: tuple[str, ...] = ("free", "grasp")
#: How far (rad) a grasp's approach axis may be from the way into its cell.
GRASP_TOLERANCE = math.radians(10.0)
#: Weight (m/rad) of the approach axis's error against the position's in a grasp's IK steps.
_GRASP_WEIGHT = 0.2
#: Version of the problem-set ``.npz`` layout written by :meth:`ProblemSet.save`.
PROBLEM_FORMAT = 1

_F64 = torch.float64


def select_families(names, leave_out=()) -> tuple[str, ...]:
    """The families ``names`` stand for (family names or :data:`FAMILY_GROUPS` keys, in that order,
    each once), without those in ``leave_out`` (family names): the bookkeeping of a leave-one-family-out
    run. Raises :class:`~kinlearn.errors.ConfigError` for an unknown name, a left-out family that was not
    chosen, or nothing left."""
    names, leave_out = (names,) if isinstance(names, str) else tuple(names), tuple(leave_out)
    known = ", ".join((*FAMILY_GROUPS, *FAMILIES))
    chosen: list[str] = []
    for name in names:
        if name not in FAMILY_GROUPS and name not in FAMILIES:
            raise ConfigError(f"unknown problem family {name!r}; choose from {known}")
        chosen += [f for f in FAMILY_GROUPS.get(name, (name,)) if f not in chosen]
    for f in leave_out:
        if f not in chosen:
            raise ConfigError(f"cannot leave out {f!r}: it is not among the chosen families {chosen}")
    kept = tuple(f for f in chosen if f not in leave_out)
    if not kept:
        raise ConfigError(f"no family left to train on: {chosen} all left out")
    return kept


#: What the error without OMPL names as needing it.
_VERIFY = "verifying problems (pass ProblemConfig(verify=False) to skip it)"


@dataclass(frozen=True)
class ProblemConfig:
    """How problems are generated and verified (see the module docstring)."""

    joint_margin: float = 0.05  # rad inside each joint limit, for start and goal
    min_clearance: float = 0.001  # m, start and goal: body–scene and self-collision distance
    min_ee_distance: float = 0.2  # m between the start and goal end effectors
    ik_batch: int = 96  # random initial configurations per IK target batch
    ik_iterations: int = 60
    ik_tolerance: float = 0.01  # m: an IK solution must put the end effector this close to its target
    max_attempts: int = 60  # scenes tried per problem before giving up
    verify: bool = True  # run RRT-Connect on every problem
    time_limit: float = 5.0  # s, RRT-Connect's limit for a problem to count as solvable
    max_travel: float = 0.01  # m of sphere travel between checked configurations (motion checks)
    dense_body: bool = False  # the 46-sphere body instead of the 12-sphere one (+ base cover)
    #: The body problems are made for: a sphere set of the robot's model, or None for the body its
    #: planner checks with (:func:`~kinlearn.collision.body.planning_body`: the ur5's carries its tool).
    sphere_set: str | None = None
    #: How the hand is held at the targets: ``"free"`` (IK for the position alone, any orientation) or
    #: ``"grasp"`` (in the families with cells, the hand's approach axis within
    #: :data:`GRASP_TOLERANCE` of the way into the cell, as a gripper holding something there points:
    #: :attr:`~kinlearn.data.scenes.SceneLayout.approach`; the other families as ``"free"``).
    hand: str = "free"
    #: Whose joint limits starts and goals (and the verifying search) keep within: ``"robot"`` (the
    #: robot's) or ``"body"`` (the problem body's, :attr:`~kinlearn.collision.BodySpheres.limits`: the
    #: ur5's tool model turns ±π, as the standard benchmarks' UR5 does, where kinlearn's ur5 turns ±2π).
    within: str = "robot"

    def __post_init__(self):
        for name in (
            "joint_margin",
            "min_clearance",
            "min_ee_distance",
            "ik_tolerance",
            "time_limit",
            "max_travel",
        ):
            value = getattr(self, name)
            value = as_real(value, f"ProblemConfig.{name}", minimum=0.0, expected="a finite number >= 0")
            object.__setattr__(self, name, value)
        for name in ("ik_batch", "ik_iterations", "max_attempts"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"ProblemConfig.{name} must be an integer >= 1, got {value!r}")
        if self.time_limit <= 0 or self.max_travel <= 0:
            raise ConfigError("ProblemConfig.time_limit and max_travel must be > 0")
        if self.within not in ("robot", "body"):
            raise ConfigError(f"ProblemConfig.within must be 'robot' or 'body', got {self.within!r}")
        if self.hand not in HANDS:
            raise ConfigError(f"ProblemConfig.hand must be one of {', '.join(HANDS)}, got {self.hand!r}")
        if self.sphere_set is not None and (not isinstance(self.sphere_set, str) or self.dense_body):
            raise ConfigError(
                f"ProblemConfig.sphere_set must be a set's name and not given with dense_body, got {self.sphere_set!r}"
            )

    def body(self, robot: Robot) -> BodySpheres:
        """The body problems are made for (see ``sphere_set`` and ``dense_body``)."""
        if self.dense_body:
            return body_spheres(robot, dense=True)
        if self.sphere_set is None:
            return planning_body(robot)
        return body_spheres(robot, sphere_set=self.sphere_set)


def problem_seed(seed: int, index: int) -> int:
    """The sub-seed of problem ``index`` of a set generated with ``seed`` (a 63-bit integer)."""
    x = (int(seed) * 0x9E3779B97F4A7C15 + int(index) * 0xBF58476D1CE4E5B9 + 0x94D049BB133111EB) % (1 << 64)
    x ^= x >> 31
    x = (x * 0xD6E8FEB86659FD93) % (1 << 64)
    return (x ^ (x >> 29)) & ((1 << 63) - 1)


# --------------------------------------------------------------------------------------------------
# Scene families. Each builder returns (boxes, spheres, start-target sampler, goal-target sampler);
# a sampler maps (n, generator) to (n, 3) end-effector targets. All numbers in metres.
# --------------------------------------------------------------------------------------------------


def _box(cx, cy, cz, hx, hy, hz) -> list[float]:
    return [float(cx), float(cy), float(cz), float(hx), float(hy), float(hz)]


def _tabletop(gen: torch.Generator):
    top = _u(gen, 0.0, 0.25)
    x0 = _u(gen, 0.3, 0.4)
    depth = _u(gen, 0.55, 0.8)
    half_w = _u(gen, 0.55, 0.8)
    yc = _u(gen, -0.1, 0.1)
    boxes = [_box(x0 + depth / 2, yc, top - 0.02, depth / 2, half_w, 0.02)]
    spheres = []
    objects = []  # (x, y, footprint radius, height of the top)
    for _ in range(_randint(gen, 2, 6)):
        for _try in range(20):  # a spot within reach, on the table, not on another object
            rad, ang = _u(gen, 0.4, 0.8), _u(gen, -1.2, 1.2)
            x, y = rad * math.cos(ang), rad * math.sin(ang)
            if x0 + 0.06 < x < x0 + depth - 0.06 and abs(y - yc) < half_w - 0.06:
                if all(math.hypot(x - ox, y - oy) > fr + 0.1 for ox, oy, fr, _ in objects):
                    break
        else:
            continue
        if float(torch.rand((), generator=gen)) < 0.5:
            hx, hy, hz = _u(gen, 0.02, 0.07), _u(gen, 0.02, 0.07), _u(gen, 0.05, 0.2)
            boxes.append(_box(x, y, top + hz, hx, hy, hz))
            objects.append((x, y, math.hypot(hx, hy), top + 2 * hz))
        else:
            r = _u(gen, 0.03, 0.08)
            spheres.append([x, y, top + r, r])
            objects.append((x, y, r, top + 2 * r))
    if len(objects) < 2:  # too crowded to place two objects: the caller draws another scene
        return None
    first = _randint(gen, 0, len(objects) - 1)
    second = (first + _randint(gen, 1, len(objects) - 1)) % len(objects)

    def behind(k: int, other: int):
        x, y, footprint, height = objects[k]
        away = math.atan2(y - objects[other][1], x - objects[other][0])

        def sample(n: int, g: torch.Generator) -> torch.Tensor:
            """Targets behind object k as seen from the other object (within ±60°), 7–14 cm from its
            footprint, from 4 cm above the table to 5 cm above the object's top."""
            ang = away + _u(g, -math.pi / 3, math.pi / 3, n)
            off = footprint + _u(g, 0.07, 0.14, n)
            z = top + 0.04 + (height - top + 0.01) * torch.rand(n, generator=g, dtype=_F64)
            return torch.stack([x + off * torch.cos(ang), y + off * torch.sin(ang), z], dim=1)

        return sample

    return boxes, spheres, behind(first, second), behind(second, first)


def _shelf(gen: torch.Generator):
    t = 0.02  # board thickness (half: 0.01)
    x_open = _u(gen, 0.5, 0.7)  # the shelf's open face, towards the robot
    depth = _u(gen, 0.3, 0.4)
    half_w = _u(gen, 0.3, 0.45)
    yc = _u(gen, -0.15, 0.15)
    bottom = _u(gen, 0.0, 0.3)
    levels = _randint(gen, 2, 3)
    level_h = _u(gen, 0.32, 0.42)
    height = levels * level_h
    xc = x_open + depth / 2
    boxes = [
        _box(x_open + depth - t / 2, yc, bottom + height / 2, t / 2, half_w, height / 2),  # back
        _box(xc, yc - half_w + t / 2, bottom + height / 2, depth / 2, t / 2, height / 2),  # sides
        _box(xc, yc + half_w - t / 2, bottom + height / 2, depth / 2, t / 2, height / 2),
        _box(xc, yc, bottom + t / 2, depth / 2, half_w, t / 2),  # bottom
        _box(xc, yc, bottom + height - t / 2, depth / 2, half_w, t / 2),  # top
    ]
    boxes += [_box(xc, yc, bottom + k * level_h, depth / 2, half_w, t / 2) for k in range(1, levels)]
    divided = float(torch.rand((), generator=gen)) < 0.5
    if divided:
        boxes.append(_box(xc, yc, bottom + height / 2, depth / 2, t / 2, height / 2))
    # Compartments: (level, column) → inner bounds.
    columns = (
        [(yc - half_w + t, yc - t / 2), (yc + t / 2, yc + half_w - t)]
        if divided
        else [(yc - half_w + t, yc + half_w - t)]
    )
    cells = [(k, c) for k in range(levels) for c in range(len(columns))]
    goal_cell = cells[_randint(gen, 0, len(cells) - 1)]
    others = [c for c in cells if c != goal_cell]
    start_inside = float(torch.rand((), generator=gen)) < 0.5
    start_cell = others[_randint(gen, 0, len(others) - 1)]

    def inside(cell):
        k, c = cell
        lo, hi = columns[c]

        def sample(n: int, g: torch.Generator) -> torch.Tensor:
            x = x_open + _u(g, 0.05, 0.15, n)
            y = lo + 0.09 + (hi - lo - 0.18) * torch.rand(n, generator=g, dtype=_F64)
            z = bottom + k * level_h + 0.1 + (level_h - 0.2) * torch.rand(n, generator=g, dtype=_F64)
            return torch.stack([x, y, z], dim=1)

        return sample

    def in_front(n: int, g: torch.Generator) -> torch.Tensor:
        x = x_open - _u(g, 0.12, 0.3, n)
        y = yc + _u(g, -half_w, half_w, n)
        z = bottom + _u(g, 0.1, height, n)
        return torch.stack([x, y, z], dim=1)

    return boxes, [], (inside(start_cell) if start_inside else in_front), inside(goal_cell)


def _barrier(gen: torch.Generator):
    xc = _u(gen, 0.5, 0.65)
    hx = _u(gen, 0.2, 0.3)
    yc = _u(gen, -0.05, 0.05)
    hy = _u(gen, 0.01, 0.03)
    top = _u(gen, 0.35, 0.8)
    boxes = [_box(xc, yc, top / 2, hx, hy, top / 2)]
    side = 1.0 if float(torch.rand((), generator=gen)) < 0.5 else -1.0

    def beside(sign: float):
        def sample(n: int, g: torch.Generator) -> torch.Tensor:
            x = xc + _u(g, -hx + 0.05, hx - 0.05, n)
            y = yc + sign * (hy + _u(g, 0.12, 0.3, n))
            z = _u(g, 0.1, max(0.15, top - 0.05), n)
            return torch.stack([x, y, z], dim=1)

        return sample

    return boxes, [], beside(side), beside(-side)


_BUILDERS: dict[str, Callable] = {"tabletop": _tabletop, "shelf": _shelf, "barrier": _barrier}


def _turn(boxes: torch.Tensor, spheres: torch.Tensor, k: int):
    """Rotate boxes and spheres by k · 90° about z (boxes stay axis-aligned: their x/y extents swap)."""
    c, s = round(math.cos(k * math.pi / 2)), round(math.sin(k * math.pi / 2))
    R = torch.tensor([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=_F64)
    b = boxes.clone()
    b[:, :3] = boxes[:, :3] @ R.T
    if k % 2:
        b[:, 3], b[:, 4] = boxes[:, 4], boxes[:, 3]
    sp = spheres.clone()
    sp[:, :3] = spheres[:, :3] @ R.T
    return b, sp, R


# --------------------------------------------------------------------------------------------------
# Problem sets
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class ProblemSet:
    """``N`` problems: joints ``start``/``goal`` ``(N, dof)`` (float64), ``scene`` of batch ``(N,)``
    (padded, with masks), ``family`` ``(N,)`` (index into :data:`FAMILIES`), ``hard`` ``(N,)`` (the
    straight joint-space line collides), ``seed`` ``(N,)`` (each problem's sub-seed), ``solve_time``
    ``(N,)`` (RRT-Connect's verification time, s; NaN if not verified) and the generation ``config``."""

    robot: str
    start: torch.Tensor
    goal: torch.Tensor
    scene: Scene
    family: torch.Tensor
    hard: torch.Tensor
    seed: torch.Tensor
    solve_time: torch.Tensor
    config: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.start.shape[0])

    def __getitem__(self, index) -> ProblemSet:
        """A subset (``problems[:10]``, ``problems[problems.hard]``, ``problems.of("shelf")``)."""
        if isinstance(index, int):
            index = [index]
        return ProblemSet(
            self.robot,
            self.start[index],
            self.goal[index],
            self.scene[index],
            self.family[index],
            self.hard[index],
            self.seed[index],
            self.solve_time[index],
            self.config,
        )

    def of(self, family: str) -> ProblemSet:
        """The problems of one family."""
        if family not in FAMILIES:
            raise ConfigError(f"unknown problem family {family!r}; choose one of {', '.join(FAMILIES)}")
        return self[self.family == FAMILIES.index(family)]

    @property
    def body_name(self) -> str | None:
        """The sphere set the problems were made for (their starts and goals are free for it), or None
        for sets written before it was recorded (made for the robot's default body)."""
        parts = self.config.get("parts", [self.config])
        names = {p.get("body") for p in parts}
        if len(names) > 1:
            raise DatasetError(f"the set's parts were made for different bodies: {sorted(map(str, names))}")
        return names.pop() if names else None

    @property
    def within(self) -> str:
        """Whose joint limits the problems were made within (:attr:`ProblemConfig.within`): ``"robot"``
        (also for sets written before it was recorded) or ``"body"``."""
        parts = self.config.get("parts", [self.config])
        # a part records its ProblemConfig's fields, or (the benchmark's sets) holds them as "problem_config"
        kinds = {p.get("within", (p.get("problem_config") or {}).get("within", "robot")) for p in parts}
        if len(kinds) > 1:
            raise DatasetError(f"the set's parts were made within different limits: {sorted(kinds)}")
        return kinds.pop()

    def body(self, robot: Robot) -> BodySpheres:
        """The body the problems were made for: the one to judge plans on them with."""
        name, default = self.body_name, body_spheres(robot)
        if name is None or name == default.name:
            return default
        return body_spheres(robot, sphere_set=name)  # "dense" too: the iiwa14's dense body is a named set

    def problem(self, i: int) -> tuple[torch.Tensor, torch.Tensor, Scene]:
        """Problem ``i`` as ``(start (dof,), goal (dof,), unbatched scene without padding)``."""
        return self.start[i], self.goal[i], self.scene[i : i + 1].unstack()[0]

    @staticmethod
    def concat(sets: list[ProblemSet]) -> ProblemSet:
        if not sets or len({s.robot for s in sets}) != 1:
            raise ConfigError("ProblemSet.concat needs at least one set, all for the same robot")
        scenes = [sc for s in sets for sc in s.scene.unstack()]
        return ProblemSet(
            sets[0].robot,
            torch.cat([s.start for s in sets]),
            torch.cat([s.goal for s in sets]),
            Scene.stack(scenes),
            torch.cat([s.family for s in sets]),
            torch.cat([s.hard for s in sets]),
            torch.cat([s.seed for s in sets]),
            torch.cat([s.solve_time for s in sets]),
            {"parts": [s.config for s in sets]},
        )

    def save(self, path: str | Path) -> Path:
        """Write the set to ``path`` (``.npz``) atomically."""
        arrays = {
            "start": self.start.detach().cpu().double().numpy(),
            "goal": self.goal.detach().cpu().double().numpy(),
            "family": self.family.cpu().numpy().astype(np.int8),
            "hard": self.hard.cpu().numpy(),
            "seed": self.seed.cpu().numpy().astype(np.int64),
            "solve_time": self.solve_time.cpu().numpy().astype(np.float32),
        }
        arrays.update({f"scene_{k}": v for k, v in self.scene.arrays().items()})
        config = {"problem_format": PROBLEM_FORMAT, "families": list(FAMILIES), "generation": self.config}
        return save_npz(path, kind="obstacle_problems", robot=self.robot, config=config, arrays=arrays)

    @classmethod
    def load(cls, path: str | Path, robot: str | None = None) -> ProblemSet:
        """Read a set written by :meth:`save`. Raises :class:`~kinlearn.errors.DatasetError` for a missing
        or unreadable file, a file of another kind, format or robot, or inconsistent contents."""
        meta, arrays = load_npz(path, kind="obstacle_problems", robot=robot)
        config = meta.get("config", {})
        if config.get("problem_format") != PROBLEM_FORMAT:
            raise DatasetError(
                f"{path} holds problem format {config.get('problem_format')!r}; this kinlearn reads {PROBLEM_FORMAT}"
            )
        stored = list(config.get("families", []))
        unknown = [f for f in stored if f not in FAMILIES]
        if not stored or unknown:
            raise DatasetError(
                f"{path} names families {stored}; this kinlearn knows {list(FAMILIES)}"
                + (f" (not {unknown})" if unknown else "")
            )
        renumber = np.array([FAMILIES.index(f) for f in stored], dtype=np.int64)
        try:
            scene = Scene.from_arrays({k[6:]: v for k, v in arrays.items() if k.startswith("scene_")})
            start = torch.as_tensor(arrays["start"], dtype=_F64)
            out = cls(
                meta["robot"],
                start,
                torch.as_tensor(arrays["goal"], dtype=_F64),
                scene,
                torch.as_tensor(renumber[arrays["family"].astype(np.int64)]),
                torch.as_tensor(arrays["hard"]),
                torch.as_tensor(arrays["seed"]),
                torch.as_tensor(arrays["solve_time"].astype(np.float64)),
                config.get("generation", {}),
            )
        except (KeyError, ObstacleError, ValueError, TypeError) as exc:
            raise DatasetError(
                f"{path} is not a consistent obstacle problem set ({type(exc).__name__}: {exc})"
            ) from exc
        n = len(out)
        shapes_ok = (
            out.start.ndim == 2
            and out.goal.shape == out.start.shape
            and out.scene.batch_shape == (n,)
            and all(t.shape == (n,) for t in (out.family, out.hard, out.seed, out.solve_time))
        )
        if not shapes_ok:
            raise DatasetError(f"{path}: arrays of inconsistent shapes (start {tuple(out.start.shape)})")
        return out

    def summary(self) -> dict:
        """Per family: number of problems, share of hard ones, median verification time."""
        out = {}
        for name in FAMILIES:
            sub = self.of(name)
            if len(sub):
                out[name] = {
                    "n": len(sub),
                    "hard": float(sub.hard.double().mean()),
                    "median_solve_time_s": float(sub.solve_time.nanmedian())
                    if bool(torch.isfinite(sub.solve_time).any())
                    else None,
                }
        return out


def _limits(body: BodySpheres, cfg: ProblemConfig) -> tuple[torch.Tensor, torch.Tensor]:
    """The joint limits problems keep within (:attr:`ProblemConfig.within`), float64 tensors."""
    if cfg.within == "body":
        return torch.as_tensor(body.limits[0], dtype=_F64), torch.as_tensor(body.limits[1], dtype=_F64)
    return body.robot.limits(_F64)


def _pick_valid(
    body: BodySpheres,
    scene: Scene,
    sampler,
    gen: torch.Generator,
    cfg: ProblemConfig,
    approach: np.ndarray | None = None,
) -> torch.Tensor | None:
    """IK from random joints towards targets drawn by ``sampler``; the first valid solution, or None.
    With ``approach`` (unit, base frame), the hand's approach axis must also lie within
    :data:`GRASP_TOLERANCE` of it (a grasp: :attr:`ProblemConfig.hand`)."""
    robot = body.robot
    kin = kinematics(robot, "fast")
    targets = sampler(cfg.ik_batch, gen)
    lo, hi = _limits(body, cfg)
    q0 = robot.sample(cfg.ik_batch, gen, dtype=_F64, margin=cfg.joint_margin, limits=(lo, hi))
    q_lo, q_hi = lo + cfg.joint_margin, hi - cfg.joint_margin
    q = dls_step(kin, q0, targets, iterations=cfg.ik_iterations, damping=0.02, clamp=True)
    if approach is not None:  # then the hand turned into the cell, the position held
        d = torch.as_tensor(approach, dtype=_F64).expand(cfg.ik_batch, 3)
        q = pointing_dls_step(
            kin, q, targets, d, iterations=cfg.ik_iterations, damping=0.02, weight=_GRASP_WEIGHT
        )
    ok = (kin.position(q, validate=False) - targets).norm(dim=-1) <= cfg.ik_tolerance
    ok &= ((q >= q_lo) & (q <= q_hi)).all(dim=-1)
    if approach is not None:
        a = kin.pose(q, validate=False)[:, :3, :3] @ torch.as_tensor(approach_axis(robot), dtype=_F64)
        ok &= (a @ torch.as_tensor(approach, dtype=_F64)) >= math.cos(GRASP_TOLERANCE)
    if not bool(ok.any()):
        return None
    d, s = clearances(body, q[ok], scene, validate=False)
    good = (d >= cfg.min_clearance) & (s >= cfg.min_clearance)
    if not bool(good.any()):
        return None
    return q[ok][good][0]


def _layout(family: str, gen: torch.Generator, scale: float, tool: float = 0.0):
    """One scene of ``family``, its start and goal target samplers (base frame) and the way a hand
    points into its cells (None: no cells, or a legacy family), or None."""
    if family not in LEGACY_FAMILIES:
        layout = build_scene(family, gen, scale, tool=tool)
        return layout.scene(), layout.start, layout.goal, layout.approach
    built = _BUILDERS[family](gen)
    if built is None:
        return None
    boxes, spheres, start_sampler, goal_sampler = built
    turn = (0, 1, 3)[_randint(gen, 0, 2)]
    bx = torch.tensor(boxes, dtype=_F64).reshape(-1, 6)
    sp = torch.tensor(spheres, dtype=_F64).reshape(-1, 4)
    bx, sp, R = _turn(bx, sp, turn)
    if scale != 1.0:  # sized for the iiwa14's reach: every position and size by the arm's scale
        bx, sp = bx * scale, sp * scale
    scene = Scene(sp, bx, floor=torch.tensor(0.0, dtype=_F64))

    def turned(sampler):
        if scale == 1.0:
            return lambda n, g: sampler(n, g) @ R.T
        return lambda n, g: scale * (sampler(n, g) @ R.T)

    return scene, turned(start_sampler), turned(goal_sampler), None


def _one_problem(
    family: str, body: BodySpheres, sub_seed: int, cfg: ProblemConfig, scale: float = 1.0, tool: float = 0.0
):
    gen = torch.Generator().manual_seed(sub_seed)
    kin = kinematics(body.robot, "fast")
    for attempt in range(cfg.max_attempts):
        built = _layout(family, gen, scale, tool)
        if built is None:
            continue
        scene, start_sampler, goal_sampler, approach = built
        if cfg.hand == "free":
            approach = None
        start = _pick_valid(body, scene, start_sampler, gen, cfg, approach)
        if start is None:
            continue
        goal = _pick_valid(body, scene, goal_sampler, gen, cfg, approach)
        if goal is None:
            continue
        if float((kin.position(start) - kin.position(goal)).norm()) < cfg.min_ee_distance:
            continue
        line = check_path(body, torch.stack([start, goal]), scene, max_travel=cfg.max_travel)
        solve_time = math.nan
        if cfg.verify:
            bounds = tuple(t.numpy() for t in _limits(body, cfg))
            rrt = OmplRrtConnect(
                body.robot, body, scene, max_travel=cfg.max_travel, why=_VERIFY, bounds=bounds
            )
            path, solve_time = rrt.solve(start, goal, time_limit=cfg.time_limit, seed=sub_seed + attempt)
            if path is None:
                continue
        return start, goal, scene, not bool(line.collision_free), solve_time, attempt
    raise PlanningError(
        f"no valid {family} problem in {cfg.max_attempts} scenes for sub-seed {sub_seed}; raise max_attempts"
    )


def make_problems(
    family: str,
    n: int,
    seed: int,
    robot: Robot | None = None,
    config: ProblemConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
    first: int = 0,
) -> ProblemSet:
    """``n`` verified problems of ``family`` (one of :data:`FAMILIES`) for ``robot`` (default the
    iiwa14; any arm with a sphere body), seeded by ``seed``; the families of
    :mod:`~kinlearn.data.scenes` are sized by the arm's :func:`~kinlearn.data.scenes.scene_scale`
    (to 0.01).

    Problem i depends on ``(seed, i)`` only (:func:`problem_seed`); ``first`` starts the set at problem
    ``first`` of that sequence (to generate a long set in parts). ``progress(done, n)`` is called after
    each problem. Raises :class:`~kinlearn.errors.ConfigError` for an unknown family or bad ``n``,
    :class:`~kinlearn.errors.RobotDescriptionError` for a robot without a sphere model, and
    :class:`~kinlearn.errors.MissingDependencyError` when verifying without OMPL.
    """
    if family not in FAMILIES:
        raise ConfigError(f"unknown problem family {family!r}; choose one of {', '.join(FAMILIES)}")
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ConfigError(f"n must be an integer >= 1, got {n!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError(f"seed must be an integer >= 0, got {seed!r}")
    if isinstance(first, bool) or not isinstance(first, int) or first < 0:
        raise ConfigError(f"first must be an integer >= 0, got {first!r}")
    cfg = config or ProblemConfig()
    robot = robot or load_robot("iiwa14")
    body = cfg.body(robot).double()
    scale = round(scene_scale(robot), 2)
    # A tool on the flange (the ur5's planning body): how much further than the bare arm it reaches.
    tool = max(0.0, round(body.reach_past_end_effector() - body_spheres(robot).reach_past_end_effector(), 2))
    if cfg.verify:
        import_ompl(_VERIFY)
    starts, goals, scenes, hard, seeds, times = [], [], [], [], [], []
    for i in range(n):
        sub = problem_seed(seed, first + i)
        start, goal, scene, is_hard, solve_time, _ = _one_problem(family, body, sub, cfg, scale, tool)
        starts.append(start)
        goals.append(goal)
        scenes.append(scene)
        hard.append(is_hard)
        seeds.append(sub)
        times.append(solve_time)
        if progress is not None:
            progress(i + 1, n)
    return ProblemSet(
        robot.name,
        torch.stack(starts),
        torch.stack(goals),
        Scene.stack(scenes),
        torch.full((n,), FAMILIES.index(family), dtype=torch.int64),
        torch.tensor(hard, dtype=torch.bool),
        torch.tensor(seeds, dtype=torch.int64),
        torch.tensor(times, dtype=_F64),
        {
            "family": family,
            "n": n,
            "seed": seed,
            "first": first,
            "scale": scale,
            **asdict(cfg),
            "body": body.name,
        },
    )
