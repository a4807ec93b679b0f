"""The arm's collision body as spheres fixed to its links, placed by the fast forward kinematics, and
the bodies a robot has.

:class:`BodySpheres` maps joints ``(..., dof)`` to world (base-frame) sphere centres ``(..., M, 3)``,
batched and differentiable; it also carries each sphere's radius and link, the sphere pairs checked
for self-collision, which spheres the floor applies to, and a bound on how far each sphere can travel
per radian of each joint (used by the dense path check; the bounds: :mod:`kinlearn.collision.body_bounds`).

:func:`body_spheres` builds a robot's body from its sphere model or spherized URDF (read by
:mod:`kinlearn.collision.sphere_models`, whose names are importable from here too), with the sphere pairs
its self-collision check takes: pairs on links at least two apart (:func:`_default_pairs`), less the link
pairs the model excludes and the pairs that overlap almost everywhere (:func:`always_overlapping`).
:func:`planning_body` is the body a planner checks its plans with.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch
from torch import nn

from ..body.kinematics import FastKinematics, _snap, _z_to_axis, kinematics
from ..body.robot import Robot
from ..errors import ConfigError, RobotDescriptionError
from ..memo import remembered
from .body_bounds import _axis_distances as _axis_distances
from .body_bounds import _lever_arms, _travel, floor_applies
from .sphere_models import (
    SPHERE_FILE,
    _model_path,
    _read_model,
    cover_cylinder,
    sphere_sets,
    urdf_limits,
    urdf_spheres,
)
from .sphere_models import SPHERE_FORMAT as SPHERE_FORMAT

__all__ = ["SPHERE_FILE", "BodySpheres", "body_spheres", "cover_cylinder", "planning_body", "sphere_sets"]


class BodySpheres(nn.Module):
    """Collision spheres fixed to a robot's links: joints ``(..., dof)`` → centres ``(..., M, 3)``.

    Buffers (move with ``.to()``): ``local`` ``(M, 3)`` centres in their link's frame, ``radii``
    ``(M,)``, ``link`` ``(M,)`` (0 = base, k = the link joint k moves), ``pairs`` ``(P, 2)`` the sphere
    pairs checked for self-collision, ``floor_mask`` ``(M,)`` the spheres the floor applies to (all but
    those resting on the mount, :func:`floor_applies`: the base stands on it), ``lever`` ``(M, dof)`` metres a sphere can travel per radian of
    each joint at most. Differentiable in the joints; dtype and device of the output follow ``q``.
    ``limits``: the joint limits ``(lower, upper)`` of the model the spheres were read from, where it gives
    the joints a narrower range than the robot's own (default: the robot's); :attr:`limits` holds them
    within the robot's.
    """

    def __init__(
        self,
        robot: Robot,
        spheres: np.ndarray,
        pairs: np.ndarray,
        name: str = "",
        limits: tuple[np.ndarray, np.ndarray] | None = None,
    ):
        super().__init__()
        spheres = np.asarray(spheres, dtype=np.float64)
        if spheres.ndim != 2 or spheres.shape[1] != 5 or spheres.shape[0] == 0:
            raise RobotDescriptionError(
                f"sphere table must have shape (M, 5) [link, x, y, z, r], got {spheres.shape}"
            )
        link = spheres[:, 0].astype(np.int64)
        if (link < 0).any() or (link > robot.dof).any() or (spheres[:, 0] != link).any():
            raise RobotDescriptionError(
                f"sphere links must be integers in 0…{robot.dof}, got {sorted(set(spheres[:, 0]))}"
            )
        if not (np.isfinite(spheres).all() and (spheres[:, 4] > 0).all()):
            raise RobotDescriptionError("sphere centres must be finite and radii > 0")
        self.robot = robot
        self.name = name
        lo, hi = robot.lower.astype(np.float64), robot.upper.astype(np.float64)
        outer = (lo, hi)
        if limits is not None:
            model = np.asarray(limits[0], np.float64), np.asarray(limits[1], np.float64)
            if model[0].shape != (robot.dof,) or model[1].shape != (robot.dof,):
                raise RobotDescriptionError(
                    f"a body's joint limits must be two arrays of {robot.dof} values, got shapes "
                    f"{model[0].shape} and {model[1].shape}"
                )
            lo, hi = np.maximum(lo, model[0]), np.minimum(hi, model[1])
            outer = np.minimum(robot.lower, model[0]), np.maximum(robot.upper, model[1])
            if not (lo < hi).all():
                raise RobotDescriptionError(
                    f"a body's joint limits must leave every joint of {robot.name} a range within its own, got "
                    f"{lo.tolist()} … {hi.tolist()}"
                )
        #: The joint limits of the model the spheres describe, within the robot's own (lower, upper), float64
        #: numpy: a planner keeps its plans among obstacles inside them (the ur5's tool model: ±π).
        self.limits = (lo, hi)
        #: The widest joint limits a plan among obstacles with this body may use, float64 numpy: the robot's
        #: and its model's together. Where the model allows more than the robot (MoveIt's panda, the standard
        #: benchmarks', turns every joint up to 0.07 rad further than the Franka datasheet limits kinlearn's
        #: panda has), a problem whose start or goal lies in that band is planned within these
        #: (:meth:`joint_box`; the planner warns).
        self.outer_limits = outer
        self._kin: FastKinematics = kinematics(robot, "fast")  # type: ignore[assignment]
        self.register_buffer("local", torch.as_tensor(spheres[:, 1:4]))
        self.register_buffer("radii", torch.as_tensor(spheres[:, 4]))
        self.register_buffer("link", torch.as_tensor(link))
        self.register_buffer("pairs", torch.as_tensor(np.asarray(pairs, dtype=np.int64).reshape(-1, 2)))
        self.register_buffer(
            "floor_mask", torch.as_tensor(floor_applies(robot, link, spheres[:, 1:4], spheres[:, 4]))
        )
        self.register_buffer("lever", torch.as_tensor(_lever_arms(robot, link, spheres[:, 1:4])))
        self._reach: float | None = None
        # Fast path: spheres sorted base first; a moving sphere's centre is folded by its joint's axis
        # rotation A (the fast kinematics turns every joint axis onto z), so that the joint's motion
        # is a plain rotation about (or translation along) z applied to a constant vector.
        if (np.diff(link) < 0).any():
            raise RobotDescriptionError("spheres must be sorted by link, base (0) first")
        self._num_base = int((link == 0).sum())
        moving = link[self._num_base :]
        folded = (
            np.stack(
                [
                    _z_to_axis(robot.joints[k - 1].axis).T @ c
                    for k, c in zip(moving, spheres[self._num_base :, 1:4], strict=True)
                ]
            )
            if len(moving)
            else np.zeros((0, 3))
        )
        # centres (N, M·3) = frames (N, dof·12) @ mix + bias, frames = per joint [col0, col1, col2, origin].
        mix = np.zeros((robot.dof * 12, len(link) * 3))
        for m, (k, f) in enumerate(zip(moving, folded, strict=True), start=self._num_base):
            base = (k - 1) * 12
            for a in range(3):
                mix[base + 9 + a, 3 * m + a] = 1.0
                for col in range(3):
                    mix[base + 3 * col + a, 3 * m + a] = f[col]
        bias = np.zeros(len(link) * 3)
        bias[: 3 * self._num_base] = spheres[: self._num_base, 1:4].reshape(-1)
        self.register_buffer("_mix", torch.as_tensor(mix), persistent=False)
        self.register_buffer("_F4", torch.as_tensor(self._kin.F[: robot.dof].copy()), persistent=False)
        self.register_buffer(
            "_prismatic", torch.tensor([jt.kind == "prismatic" for jt in robot.joints]), persistent=False
        )
        self.register_buffer("_bias", torch.as_tensor(bias), persistent=False)
        self._prismatic_list = tuple(jt.kind == "prismatic" for jt in robot.joints)
        # Per joint: (translation terms [(k, t_k)], rotation columns [[(coef, k), ...] × 3]) of F_i.
        F = self._kin.F
        self._steps = [
            (
                [(k, _snap(float(F[i, k, 3]))) for k in range(3) if _snap(float(F[i, k, 3])) != 0.0],
                [
                    [(_snap(float(F[i, k, c])), k) for k in range(3) if _snap(float(F[i, k, c])) != 0.0]
                    for c in range(3)
                ],
            )
            for i in range(robot.dof)
        ]

    @property
    def reach(self) -> float:
        """How far (m) from the base's origin any part of the body can be, in any configuration: per sphere
        the fixed offsets from the base to the joint that moves its link, its offset in that link and its
        radius, added (triangle inequality: rotations keep lengths; a prismatic joint adds its largest
        travel). Nothing farther than this from the base can touch the robot."""
        if self._reach is None:
            F = self._kin.F  # F[i]: the fixed transform before joint i
            travel = _travel(self.robot)
            steps = [float(np.linalg.norm(F[i, :3, 3])) + travel[i] for i in range(self.robot.dof)]
            offsets = np.concatenate(([0.0], np.cumsum(steps)))
            link = self.link.cpu().numpy()
            local = self.local.detach().cpu().double().numpy()
            radii = self.radii.detach().cpu().double().numpy()
            self._reach = float((offsets[link] + np.linalg.norm(local, axis=1) + radii).max())
        return self._reach

    def reach_past_end_effector(self) -> float:
        """How far (m) the body reaches past the end effector: the largest distance from the end
        effector to the far side of a sphere of the last link (a bare flange's own spheres, or a tool's)."""
        q = torch.as_tensor(np.clip(np.zeros(self.robot.dof), self.robot.lower, self.robot.upper))
        q = q.to(self.local.dtype)
        centres = self(q[None], validate=False)[0]
        ee = self._kin.position(q[None], validate=False)[0]
        last = self.link == self.robot.dof
        if not bool(last.any()):
            return 0.0
        return float(((centres[last] - ee).norm(dim=-1) + self.radii[last]).max())

    @property
    def num_spheres(self) -> int:
        return int(self.radii.shape[0])

    def extra_repr(self) -> str:
        return f"robot={self.robot.name!r}, set={self.name!r}, spheres={self.num_spheres}, pairs={len(self.pairs)}"

    #: Large batches are evaluated in chunks of this many configurations (cache-resident intermediates).
    chunk: int = 8192

    def joint_box(self, theta0: np.ndarray, thetaT: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each problem's joint box a planner searches, ``(lower, upper)`` each ``(N, dof)`` for starts and
        goals ``(N, dof)``: :attr:`limits` where the problem's start and goal both lie within them (a plan
        for the benchmarks' UR5 between configurations within its ±π stays within them; a panda plan within
        the robot's own), else :attr:`outer_limits` (the robot's for the ur5; the benchmarks' MoveIt model's
        for the panda). (Widening the body's box only on the joints whose ends leave it instead cost the
        ur5's tuning problems, made within ±2π, 11 points in fixed time and 6 under a deadline of 0.05 s.)"""
        lo, hi = self.limits
        inside = ((np.minimum(theta0, thetaT) >= lo) & (np.maximum(theta0, thetaT) <= hi)).all(
            axis=1, keepdims=True
        )  # NaN is outside: it propagates through minimum and maximum and compares false
        return np.where(inside, lo, self.outer_limits[0]), np.where(inside, hi, self.outer_limits[1])

    def forward(self, q: torch.Tensor, validate: bool = True) -> torch.Tensor:
        """World sphere centres ``(..., M, 3)`` for joints ``q (..., dof)``.

        ``validate=False`` skips the shape and finiteness checks of ``q``.
        """
        flat, batch = self._kin._prepare(q, validate)
        if flat.shape[0] <= self.small:
            out = self._centres_small(flat)
        elif flat.shape[0] > self.chunk:
            out = torch.cat([self._centres_flat(c) for c in flat.split(self.chunk)])
        else:
            out = self._centres_flat(flat)
        return out.reshape(*batch, self.num_spheres, 3)

    #: Batches up to this size take :meth:`_centres_small` (fewer, larger torch operations).
    small: int = 64

    def _centres_small(self, q: torch.Tensor) -> torch.Tensor:
        """``(N, dof)`` → ``(N, M, 3)`` by 4×4 products: few operations, for small batches."""
        dt = q.dtype
        F = self._F4.to(dt)  # (dof, 4, 4) fixed transforms before each joint
        prism = self._prismatic
        c = torch.where(prism, torch.ones_like(q), torch.cos(q)).unsqueeze(-1)
        s = torch.where(prism, torch.zeros_like(q), torch.sin(q)).unsqueeze(-1)
        shift = torch.where(prism, q, torch.zeros_like(q)).unsqueeze(-1)
        n = q.shape[0]
        T = torch.stack(
            (
                c * F[..., 0] + s * F[..., 1],
                c * F[..., 1] - s * F[..., 0],
                F[..., 2].expand(n, -1, -1),
                F[..., 3] + shift * F[..., 2],
            ),
            dim=-1,
        )  # (N, dof, 4, 4): F_i · (rotation about or shift along z by q_i)
        acc = [T[:, 0]]
        for i in range(1, self.robot.dof):
            acc.append(acc[-1] @ T[:, i])
        frames = torch.stack(acc, dim=1)[..., :3, :].transpose(-1, -2).reshape(n, -1)  # [col0, col1, col2, p]
        return torch.addmm(self._bias.to(dt), frames, self._mix.to(dt)).reshape(n, -1, 3)

    def _centres_flat(self, q: torch.Tensor) -> torch.Tensor:
        """``(N, dof)`` → ``(N, M, 3)``.

        Walks the chain once with each frame held as its origin and three axis columns ``(N, 3)``:
        the fixed transforms between joints are applied as sparse combinations of columns (their
        rotations are mostly signed permutations), each joint as a rotation of two columns (or a
        shift along the third). Each sphere is then origin + Σ columns × its folded local centre.
        """
        dt = q.dtype
        p = q.new_zeros(3)
        cols = [torch.eye(3, dtype=dt, device=q.device)[k] for k in range(3)]
        cq, sq = torch.cos(q).unsqueeze(-1), torch.sin(q).unsqueeze(-1)
        frames = []
        for i in range(self.robot.dof):
            for k, t in self._steps[i][0]:
                p = p + (cols[k] if t == 1.0 else -cols[k] if t == -1.0 else cols[k] * t)
            cols = [self._combine(cols, terms) for terms in self._steps[i][1]]
            if self._prismatic_list[i]:
                p = p + cols[2] * q[:, i : i + 1]
            else:
                c, s = cq[:, i], sq[:, i]
                cols = [c * cols[0] + s * cols[1], c * cols[1] - s * cols[0], cols[2]]
            frames += [*cols, p]
        frames = torch.cat(torch.broadcast_tensors(*frames), dim=-1)  # (N, dof · 12): [col0, col1, col2, p]
        # Every centre is a fixed linear combination of the frames (base spheres: the constant term).
        return torch.addmm(self._bias.to(dt), frames, self._mix.to(dt)).reshape(q.shape[0], -1, 3)

    @staticmethod
    def _combine(cols: list[torch.Tensor], terms: list[tuple[float, int]]) -> torch.Tensor:
        out = None
        for coef, k in terms:
            x = cols[k] if coef == 1.0 else -cols[k] if coef == -1.0 else cols[k] * coef
            out = x if out is None else out + x
        return out if out is not None else torch.zeros_like(cols[0])

    centres = forward

    def radii_like(self, x: torch.Tensor) -> torch.Tensor:
        """The radii ``(M,)`` in ``x``'s dtype and device."""
        return self.radii.to(dtype=x.dtype, device=x.device)


#: The modules whose code :func:`always_overlapping` runs (a change to them is a new answer).
_CODE = (__file__, str(Path(__file__).parents[1] / "body" / "kinematics.py"))


def always_overlapping(
    robot: Robot,
    spheres: np.ndarray,
    pairs: np.ndarray,
    samples: int = 2000,
    share: float = 0.95,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Of the sphere ``pairs``, those that overlap in at least ``share`` of ``samples`` uniformly drawn
    configurations (seeded): pairs a self-collision check must leave out, as an SRDF's disabled pairs.
    Returns ``(kept pairs, each pair's overlap share (P,))``."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)

    def overlap() -> np.ndarray:
        body = BodySpheres(robot, spheres, np.zeros((0, 2), dtype=np.int64))
        q = robot.sample(samples, torch.Generator().manual_seed(seed), dtype=torch.float64)
        with torch.no_grad():
            c = body(q)
            p = torch.as_tensor(pairs)
            gap = (c[:, p[:, 0]] - c[:, p[:, 1]]).norm(dim=-1) - body.radii[p[:, 0]] - body.radii[p[:, 1]]
            return (gap < 0).double().mean(0).numpy()

    # the same robot (its URDF's bytes), spheres, pairs and draws give the same shares in every process
    parts = (robot.urdf, robot.ee_frame, robot.lower, robot.upper, np.asarray(spheres, np.float64), pairs)
    parts += (samples, seed, torch.__version__)
    frac = remembered("overlap-shares", parts, overlap, dtype=np.float64, shape=(len(pairs),), code=_CODE)
    return pairs[frac < share], frac


def _default_pairs(link: np.ndarray, adjacent_gap: int = 2) -> np.ndarray:
    """All sphere pairs on links at least ``adjacent_gap`` apart (the candidates for self-collision)."""
    i, j = np.triu_indices(len(link), k=1)
    keep = np.abs(link[i] - link[j]) >= adjacent_gap
    return np.stack([i[keep], j[keep]], axis=1)


#: Per (robot, sphere URDF, dropped links): the spheres and self-collision pairs read from it.
_URDF_BODIES: dict[tuple, tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]] = {}


def _from_urdf(
    robot: Robot, path: Path, drop_links: tuple[str, ...], rule: dict
) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]:
    key = (robot.name, robot.urdf, str(path), drop_links, json.dumps(rule, sort_keys=True))
    hit = _URDF_BODIES.get(key)
    if hit is None:
        spheres = urdf_spheres(robot, path, drop_links)
        pairs = _default_pairs(spheres[:, 0].astype(np.int64))
        excluded = {tuple(sorted(p)) for p in rule.get("excluded_link_pairs", [])}
        if excluded and len(pairs):  # link pairs an SRDF disables, or that touch everywhere
            ends = np.sort(spheres[:, 0].astype(np.int64)[pairs], axis=1)
            pairs = pairs[np.array([(int(a), int(b)) not in excluded for a, b in ends], dtype=bool)]
        kept, _ = always_overlapping(
            robot,
            spheres,
            pairs,
            samples=int(rule.get("samples", 2000)),
            share=float(rule.get("share", 0.95)),
            seed=int(rule.get("seed", 0)),
        )
        hit = _URDF_BODIES[key] = (spheres, kept, urdf_limits(robot, path))
    return hit


def body_spheres(
    robot: Robot, dense: bool = False, base: bool = True, sphere_set: str | None = None
) -> BodySpheres:
    """The collision spheres of ``robot``: its default set (the iiwa14: Drake's 12 spheres and 6 covering
    the base; panda and ur5: the spherized URDFs of ``robots/``, the panda's hand included, the ur5's arm
    alone; a robot registered with ``spheres=PATH``: that URDF), or with ``dense=True`` the iiwa14's
    46-sphere set, or the set named ``sphere_set`` (``robots/<robot>/collision_spheres.json`` lists them:
    the ur5's ``"gripper"`` carries the force–torque sensor and Robotiq gripper of the standard
    benchmarks' UR5).

    ``base=False`` leaves out the base's spheres (they never move: useful where only the arm matters).
    A set read from a URDF carries that model's joint limits (:func:`urdf_limits`, :attr:`BodySpheres.limits`).
    Raises :class:`~kinlearn.errors.RobotDescriptionError` for a robot without a sphere model or without
    the set asked for.
    """
    own = getattr(robot, "sphere_urdf", None)
    if own is not None and not dense and sphere_set is None:
        if Path(own).suffix.lower() == ".json":  # a sphere model (kinlearn.collision.spherize writes one)
            model = _read_model(str(own))
            entry = model["sets"][model.get("default_set", "fitted")]
            spheres, pairs, limits = _from_urdf(
                robot, Path(own).parent / entry["urdf"], tuple(entry.get("drop_links", ())),
                model.get("self_collision", {}),
            )  # fmt: skip
            name = model.get("default_set", "fitted")
        else:
            spheres, pairs, limits = _from_urdf(robot, Path(own), (), {})
            name = "spherized"
    else:
        model = sphere_sets(robot)
        if sphere_set is not None and dense:
            raise ConfigError("give dense=True or a sphere_set, not both")
        if sphere_set is not None:
            key = sphere_set
        else:
            key = "dense" if dense else model.get("default_set", "sparse")
        if key not in model["sets"]:
            raise RobotDescriptionError(
                f"robot {robot.name!r} has no {key!r} sphere set (it has {', '.join(model['sets'])})"
            )
        entry = model["sets"][key]
        name = key
        limits = None
        if "urdf" in entry:
            spheres, pairs, limits = _from_urdf(
                robot,
                _model_path(robot).parent / entry["urdf"],
                tuple(entry.get("drop_links", ())),
                model.get("self_collision", {}),
            )
        else:
            spheres = np.asarray(entry["spheres"], dtype=np.float64)
            if entry.get("base") == "base_cylinder_cover":
                cover = np.asarray(model["base_cylinder_cover"]["spheres"], dtype=np.float64)
                spheres = np.concatenate([cover, spheres])
            spheres = spheres[np.argsort(spheres[:, 0], kind="stable")]  # base first, then link by link
            link = spheres[:, 0].astype(np.int64)
            excluded = {tuple(p) for p in model.get("self_collision", {}).get("excluded_link_pairs", [])}
            pairs = _default_pairs(link)
            keep = np.array([(int(link[a]), int(link[b])) not in excluded for a, b in pairs], dtype=bool)
            pairs = pairs[keep] if len(pairs) else pairs
    if not base:
        moving = spheres[:, 0] > 0
        renumber = np.cumsum(moving) - 1
        keep = moving[pairs[:, 0]] & moving[pairs[:, 1]] if len(pairs) else np.zeros(0, dtype=bool)
        pairs = renumber[pairs[keep]] if len(pairs) else pairs
        spheres = spheres[moving]
    return BodySpheres(robot, spheres, pairs, name=name, limits=limits)


def planning_body(robot: Robot) -> BodySpheres:
    """The body a planner checks its plans with by default: the robot's planning set where its sphere
    model names one (``planning_set`` in ``robots/<robot>/collision_spheres.json``: the ur5's
    ``"gripper"``, its arm carrying the force–torque sensor and Robotiq gripper of the standard benchmarks'
    UR5, never narrower than the arm with that tool), else :func:`body_spheres`' default. ``judge`` and the
    obstacle baselines check with it too; problems are generated and networks trained with
    :func:`body_spheres` (the arm the robot's model describes). A plan flagged collision-free is free for
    both."""
    own = getattr(robot, "sphere_urdf", None)
    if own is None:
        name = sphere_sets(robot).get("planning_set")
        if name is not None:
            return body_spheres(robot, sphere_set=name)
    return body_spheres(robot)
