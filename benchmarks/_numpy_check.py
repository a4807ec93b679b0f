"""The NumPy dense path check the planner used at batch 1 before the compiled kernel
(``kinlearn.collision.kernel``) replaced it: kept here, outside the package, only as the baseline that
``dense_check_speed.py`` times the kernel against in the same run. It reads spheres and axis-aligned
boxes only.

Dense path checks in NumPy for planning at batch 1: the answers of :func:`check_path`, fast.

A planner that proposes a handful of candidate joint paths for one scene must pick a collision-free one
within a fraction of a millisecond. Through torch every small operation costs microseconds of dispatch,
and the dense check of one path touches hundreds of configurations. Here the body and the scene are
float64 NumPy arrays and only a small part of those configurations is evaluated, while
:func:`check_paths` returns exactly what :func:`~kinlearn.collision.check_path` returns for every path.

**The checked configurations** are those of :func:`check_path`: segment k of a path is cut into
``segment_steps`` sub-steps (the lever bound of :class:`BodySpheres`, added in torch's order so that the
counts agree to the bit); every sub-step's start and the path's last configuration are checked; one
collides when its body–scene distance is ≤ ``margin`` or a self-collision pair's distance is ≤ 0.

**Which of them are evaluated.** Each moving sphere's distance to the scene is 1-Lipschitz in its centre
(the fixed base spheres add a constant). Along segment k (joints θ_k + f Δθ_k, f ∈ [0, 1]) sphere m's
centre x(f) travels at most L = Σ_j |Δθ_j| lever_mj, and |x''| ≤ bend = Σ_j lever_mj |Δθ_j| (|Δθ_j| +
2 Σ_{i<j} |Δθ_i|) (the second derivative in joints i and j is at most the lever of joint max(i, j)), so
between two evaluated configurations a and b a fraction s of the segment apart x stays within
bend · s² / 8 of the chord from x(a) to x(b). Every configuration between them therefore has sphere m at
least

    (D_m(a) + D_m(b) − min(|x(b) − x(a)| + bend · s² / 4, L · s)) / 2

from the scene. A self-collision pair's distance changes no faster than the relative motion of its
spheres (links l < l'), which only joints l … l'−1 cause: Σ over them of |Δθ_j| · the later sphere's lever.

The check evaluates, in two vectorised rounds:

1. the knots and a grid of sub-steps on every segment, about :data:`GRID` sub-steps apart (body–scene
   distances); the self-collision pairs at the knots and, on segments whose knots do not rule out a
   self-collision, the pairs that could collide, at the grid;
2. every sub-step between two grid configurations whose bound does not rule out a distance below the
   nearest one found (it could lower the clearance), or a collision before the first one found (it could
   move ``first_collision`` earlier).

Configurations that are not evaluated provably change neither the clearance, nor the collision flag, nor
the first colliding segment. The bounds carry a slack of 1e-9 m (plus 1e-12 relative) against rounding;
the float64 error of the kinematics is ~1e-15 m.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch

from kinlearn.body.kinematics import _z_to_axis
from kinlearn.collision.body import BodySpheres
from kinlearn.collision.scene import Scene
from kinlearn.errors import ConfigError, DTypeError, NonFiniteError, ObstacleError, ShapeError

__all__ = ["GRID", "NumpyBody", "NumpyScene", "check_paths", "first_free"]

#: Sub-steps between two configurations of the first round's grid, for a segment of average length.
GRID = 16

_TINY = float(np.finfo(np.float64).tiny)  # the clamp under the square roots, as in the torch distances
_SLACK = 1e-9  # metres of slack in every bound
_REL = 1e-12
#: Configurations evaluated at once (larger batches are split, keeping temporaries in cache).
CHUNK = 512


def _tol(x):
    return _SLACK + _REL * np.abs(x)


def _torch_sum_order(n: int) -> np.ndarray:
    """A permutation of n terms whose left-to-right float64 sum equals torch's sum over a contiguous last
    dimension of size n to the bit (found by trying the orders of torch's CPU kernels on random data);
    the identity if none does (then a sub-step count could differ where a bound lies within a rounding
    error of a whole number of sub-steps)."""
    ident = np.arange(n)
    if n >= 8:  # NumPy adds 8 or more terms pairwise: no permutation reproduces another order
        return ident
    head = list(range(4, n))
    candidates = [ident, np.array([*head, 0, 1, 2, 3][:n]), np.array([0, *head, 1, 2, 3][:n])]
    rng = np.random.default_rng(0)
    x = rng.random((4, 10, 12, n)) * rng.random((4, 10, 12, 1))
    ref = torch.as_tensor(x).sum(dim=-1).numpy()
    for perm in candidates:
        if np.array_equal(x[..., perm].sum(axis=-1), ref):
            return perm
    return ident


class NumpyBody:
    """The sphere body of a :class:`BodySpheres` as float64 NumPy arrays, with its forward kinematics.

    Arrays (copies of the body's buffers): ``local`` ``(M, 3)``, ``radii`` ``(M,)``, ``link`` ``(M,)``,
    ``pairs`` ``(P, 2)``, ``floor_mask`` ``(M,)``, ``lever`` ``(M, dof)``, and the canonical fixed
    transforms ``F`` ``(dof, 4, 4)`` of the torch body's chain (every joint a rotation about, or a shift
    along, z). :meth:`centres` maps joints ``(N, dof)`` to centres ``(N, M, 3)``.
    """

    def __init__(self, body: BodySpheres):
        if not isinstance(body, BodySpheres):
            raise ConfigError(f"NumpyBody needs a BodySpheres, got {type(body).__name__}")

        def arr(t: torch.Tensor, dtype) -> np.ndarray:
            return np.ascontiguousarray(t.detach().cpu().numpy().astype(dtype))

        robot = body.robot
        self.robot = robot
        self.name = body.name
        self.dof = robot.dof
        self.local = arr(body.local, np.float64)
        self.radii = arr(body.radii, np.float64)
        self.link = arr(body.link, np.int64)
        self.pairs = arr(body.pairs, np.int64).reshape(-1, 2)
        self.floor_mask = arr(body.floor_mask, bool)
        self.lever = arr(body.lever, np.float64)
        self.F = np.asarray(body._kin.F[: self.dof], dtype=np.float64).copy()
        self.prismatic = np.array([j.kind == "prismatic" for j in robot.joints], dtype=bool)
        M, dof = len(self.radii), self.dof
        # BodySpheres sorts its spheres by link, base (link 0, never moving) first.
        nb = int((self.link == 0).sum())
        self.num_base, self.num_moving = nb, M - nb
        self._base_centres = self.local[:nb].T[:, :, None].copy()  # (3, Mb, 1)
        mlink = self.link[nb:]
        self.links = int(mlink.max()) if self.num_moving else 0  # frames needed: those of links 1 … links
        # Frames are held as H (4, 3, n): rows = the frame's three axis columns and its origin, so that
        # appending joint i is H ← Mᵢ H with Mᵢ = Rz(qᵢ)ᵀ Fᵢᵀ (4 × 4 per configuration), and Mᵢ is linear in
        # (cos qᵢ, sin qᵢ, 1[, qᵢ]): Mᵢ = basis (16, 3[+1]) @ that vector.
        FT = self.F[: self.links].transpose(0, 2, 1)
        basis = np.zeros((self.links, 4, 4, 4))  # (link, row, column, [cos, sin, 1, q])
        basis[:, 0, :, 0], basis[:, 0, :, 1] = FT[:, 0], FT[:, 1]
        basis[:, 1, :, 0], basis[:, 1, :, 1] = FT[:, 1], -FT[:, 0]
        basis[:, 2, :, 2], basis[:, 3, :, 2] = FT[:, 2], FT[:, 3]
        basis[:, 3, :, 3] = FT[:, 2]  # a prismatic joint shifts the origin along its axis
        self._prismatic = self.prismatic[: self.links]
        self._any_prismatic = bool(self._prismatic.any())
        self._basis = basis.reshape(self.links, 16, 4)[:, :, : 4 if self._any_prismatic else 3].copy()
        # Each moving sphere's centre in its link's canonical frame (axis on z), homogeneous, packed per
        # link: centre = Σ_r FHT[l, slot, r] · H_l[r] (the origin row with weight 1).
        slot = np.zeros(self.num_moving, dtype=np.int64)
        for m in range(1, self.num_moving):
            slot[m] = slot[m - 1] + 1 if mlink[m] == mlink[m - 1] else 0
        S = int(slot.max()) + 1 if self.num_moving else 1
        FHT = np.zeros((max(self.links, 1), S, 4))
        for m in range(self.num_moving):
            k = int(mlink[m])
            FHT[k - 1, slot[m], :3] = _z_to_axis(robot.joints[k - 1].axis).T @ self.local[nb + m]
            FHT[k - 1, slot[m], 3] = 1.0
        self._FHT = FHT
        self._take = (mlink - 1) * S + slot
        self._r_mov = self.radii[nb:, None].copy()  # (Mm, 1)
        fm = self.floor_mask[nb:]
        self._floor_off = None if fm.all() else np.where(fm, 0.0, np.inf)[:, None]
        self._lever_mov = self.lever[nb:].copy()  # (Mm, dof)
        # segment_steps adds |Δθ_j| · lever_mj over j in the order of torch's CPU kernel; NumPy adds a
        # short last axis left to right, so the terms are permuted to give the same bits.
        self._sum_order = _torch_sum_order(dof)
        self._lever_sum = self._lever_mov[:, self._sum_order].copy()
        # Self-collision: difference matrix (pairs, M) of ±1, the pairs' radii sums, and each pair's
        # relative lever (pairs, dof): the later sphere's lever on the joints between the two links.
        a, b = self.pairs[:, 0], self.pairs[:, 1]
        npairs = len(a)
        self._pair_diff = np.zeros((npairs, M))
        self._pair_diff[np.arange(npairs), a] = 1.0
        self._pair_diff[np.arange(npairs), b] = -1.0
        self._reach = (self.radii[a] + self.radii[b])[:, None]
        lo = np.minimum(self.link[a], self.link[b])
        hi = np.maximum(self.link[a], self.link[b])
        later = np.where(self.link[a] >= self.link[b], a, b)
        j = np.arange(dof)
        self._pair_lever = self.lever[later] * ((j >= lo[:, None]) & (j < hi[:, None]))

    def __repr__(self) -> str:
        return (
            f"NumpyBody(robot={self.robot.name!r}, set={self.name!r}, spheres={len(self.radii)}, "
            f"pairs={len(self.pairs)})"
        )

    # ---------------------------------------------------------------------------------------------
    def _fk(self, q: np.ndarray) -> np.ndarray:
        """``q (n, dof)`` → all sphere centres ``(3, M, n)`` (coordinate, sphere, configuration)."""
        n, nl, nb = q.shape[0], self.links, self.num_base
        out = np.empty((3, nb + self.num_moving, n))
        out[:, :nb] = self._base_centres
        if not (nl and n):
            return out
        qT = q.T[:nl]
        v = np.empty((nl, self._basis.shape[2], n))
        np.cos(qT, out=v[:, 0])
        np.sin(qT, out=v[:, 1])
        v[:, 2] = 1.0
        if self._any_prismatic:
            v[:, 3] = qT
            v[self._prismatic, 0] = 1.0
            v[self._prismatic, 1] = 0.0
            v[~self._prismatic, 3] = 0.0
        Mi = np.matmul(self._basis, v).reshape(nl, 4, 4, n)
        H = np.empty((nl, 4, 3, n))
        H[0] = Mi[0, :, :3]
        for i in range(1, nl):
            np.einsum("abn,brn->arn", Mi[i], H[i - 1], out=H[i])
        per_link = np.matmul(self._FHT, H.reshape(nl, 4, 3 * n)).reshape(nl * self._FHT.shape[1], 3, n)
        out[:, nb:] = per_link[self._take].transpose(1, 0, 2)
        return out

    def _self(self, c: np.ndarray, pairs: np.ndarray | None = None) -> np.ndarray:
        """Centres ``(3, M, n)`` → signed distance of the self-collision pairs ``(pairs, n)`` (all of them,
        or those indexed by ``pairs``)."""
        diff, reach = (
            (self._pair_diff, self._reach) if pairs is None else (self._pair_diff[pairs], self._reach[pairs])
        )
        v = np.matmul(diff, c)  # (3, pairs, n): exact differences (one ±1 term each)
        v *= v
        d = v.sum(axis=0)
        np.maximum(d, _TINY, out=d)
        np.sqrt(d, out=d)
        d -= reach
        return d

    def centres(self, q: np.ndarray) -> np.ndarray:
        """World sphere centres ``(N, M, 3)`` of joints ``q (N, dof)`` (float64)."""
        q = _as_joints(q, self.dof, "joint values q", "N")
        return self._fk(q).transpose(2, 1, 0).copy()


class NumpyScene:
    """One scene (no batch) as float64 NumPy arrays: ``spheres (K, 4)``, ``boxes (B, 6)`` ([centre, half
    extents]), ``floor`` (a height in metres, or None).

    Build it from arrays (``validate=False`` skips the shape, finiteness and size checks, for arrays known
    to be valid) or from an unbatched :class:`Scene` with :meth:`from_scene` (padding masks applied).
    """

    __slots__ = ("_base", "_boxes", "_oc", "_oh", "_or", "_spheres", "boxes", "floor", "spheres")

    def __init__(self, spheres=None, boxes=None, floor: float | None = None, validate: bool = True):
        s = np.zeros((0, 4)) if spheres is None else np.asarray(spheres, dtype=np.float64)
        b = np.zeros((0, 6)) if boxes is None else np.asarray(boxes, dtype=np.float64)
        if validate:
            if s.ndim != 2 or s.shape[1] != 4:
                raise ObstacleError(
                    f"spheres must have shape (K, 4) with rows [x, y, z, radius], got {s.shape}"
                )
            if b.ndim != 2 or b.shape[1] != 6:
                raise ObstacleError(
                    f"boxes must have shape (B, 6) with rows [cx, cy, cz, hx, hy, hz], got {b.shape}"
                )
            if not (np.isfinite(s).all() and np.isfinite(b).all()):
                raise ObstacleError("spheres and boxes must hold finite values only")
            if (s[:, 3] <= 0).any() or (b[:, 3:] <= 0).any():
                raise ObstacleError("every sphere radius and box half extent must be > 0 (metres)")
            if floor is not None:
                try:
                    floor = float(floor)
                except (TypeError, ValueError) as exc:
                    raise ObstacleError(
                        f"the floor height must be a number of metres or None, got {floor!r}"
                    ) from exc
                if not math.isfinite(floor):
                    raise ObstacleError("the floor height must be a finite number of metres, or None")
        self.spheres = s
        self.boxes = b
        self.floor = None if floor is None else float(floor)
        # Every obstacle as a rounded box: centre, half extents (0 for a sphere), radius (0 for a box),
        # laid out (3, K + B, 1, 1) against centres (3, m, n).
        k = s.shape[0]
        oc = np.concatenate([s[:, :3], b[:, :3]])
        oh = np.concatenate([np.zeros((k, 3)), b[:, 3:]])
        self._oc = oc.T[:, :, None, None].copy()
        self._oh = oh.T[:, :, None, None].copy()
        self._or = np.concatenate([s[:, 3], np.zeros(b.shape[0])])[:, None, None]
        self._spheres, self._boxes = k > 0, b.shape[0] > 0
        self._base: dict = {}  # NumpyBody → distance of its fixed spheres to this scene

    @classmethod
    def from_scene(cls, scene: Scene) -> NumpyScene:
        """The obstacles of an unbatched :class:`Scene`, its masked-out padding dropped."""
        if not isinstance(scene, Scene):
            raise ObstacleError(f"expected a Scene, got {type(scene).__name__}")
        if len(scene.batch_shape):
            raise ObstacleError(
                f"a NumpyScene holds one scene, got batch shape {tuple(scene.batch_shape)}; "
                "take one with scene.unstack() or scene[i]"
            )
        if not scene.axis_aligned:
            raise ObstacleError(
                "a NumpyScene holds spheres and axis-aligned boxes only; this scene has rotated boxes or "
                "cylinders (check it with kinlearn.collision.check_path)"
            )
        s = scene.spheres.detach().cpu().numpy().astype(np.float64)
        b = scene.boxes[..., :6].detach().cpu().numpy().astype(np.float64)
        if scene.sphere_mask is not None:
            s = s[scene.sphere_mask.cpu().numpy()]
        if scene.box_mask is not None:
            b = b[scene.box_mask.cpu().numpy()]
        floor = None if scene.floor is None else float(scene.floor)
        return cls(s, b, floor, validate=False)

    @property
    def num_spheres(self) -> int:
        return int(self.spheres.shape[0])

    @property
    def num_boxes(self) -> int:
        return int(self.boxes.shape[0])

    def __repr__(self) -> str:
        floor = "none" if self.floor is None else f"{self.floor:.3f} m"
        return f"NumpyScene(spheres={self.num_spheres}, boxes={self.num_boxes}, floor={floor})"

    # ---------------------------------------------------------------------------------------------
    def _distances(self, c: np.ndarray, r: np.ndarray, floor_off: np.ndarray | None) -> np.ndarray:
        """Centres ``c (3, m, n)``, radii ``r (m, 1)``, floor offsets ``(m, 1)`` (0, or +inf where the floor
        does not apply; None: it applies to all) → each sphere's signed distance to the scene ``(m, n)``.

        The arithmetic of :func:`~kinlearn.collision.body_obstacle_distance`, with a sphere obstacle taken
        as a box of half extents 0 minus its radius: with q = |p − c| − h, √max(Σ max(q, 0)², tiny) +
        min(max q, 0) − radius, which for h = 0 is √max(|p − c|², tiny) − radius to the last bit.
        """
        if self._spheres or self._boxes:
            q = c[:, None] - self._oc  # (3, K + B, m, n)
            if self._boxes:
                np.abs(q, out=q)
                q -= self._oh
                inside = q.max(axis=0)
                np.minimum(inside, 0.0, out=inside)
                np.maximum(q, 0.0, out=q)
            q *= q
            d = q.sum(axis=0)
            np.maximum(d, _TINY, out=d)
            np.sqrt(d, out=d)
            if self._boxes:
                d += inside
            if self._spheres:
                d -= self._or
            d = d.min(axis=0)
            d -= r
        else:
            d = np.full(c.shape[1:], np.inf)
        if self.floor is not None:
            f = c[2] - r
            f -= self.floor
            if floor_off is not None:
                f += floor_off
            np.minimum(d, f, out=d)
        return d

    def _base_distance(self, body: NumpyBody) -> float:
        """The smallest signed distance of ``body``'s fixed spheres to this scene (cached per body)."""
        hit = self._base.get(body)
        if hit is None:
            nb = body.num_base
            hit = math.inf
            if nb:
                off = np.where(body.floor_mask[:nb], 0.0, np.inf)[:, None]
                hit = float(self._distances(body._base_centres, body.radii[:nb, None], off).min())
            self._base[body] = hit
        return hit


def _as_joints(x, dof: int, what: str, layout: str) -> np.ndarray:
    """``x`` as a C-contiguous float64 array of shape ``(layout, dof)``; typed errors otherwise."""
    if isinstance(x, torch.Tensor):
        x = x.detach().cpu().numpy()
    a = np.asarray(x)
    if a.dtype.kind != "f":
        raise DTypeError(f"{what} must hold real floating-point numbers, got dtype {a.dtype}")
    if a.ndim != layout.count(",") + 2 or a.shape[-1] != dof:
        raise ShapeError(f"{what} must have shape ({layout}, {dof}), got {a.shape}")
    a = np.ascontiguousarray(a, dtype=np.float64)
    if not np.isfinite(a).all():
        n = int((~np.isfinite(a)).sum())
        raise NonFiniteError(f"{what} holds {n} NaN/inf value(s); all values must be finite")
    return a


def _check_args(body, scene, max_travel, margin) -> None:
    if not isinstance(body, NumpyBody):
        raise ConfigError(
            f"body must be a NumpyBody (NumpyBody(body_spheres(robot))), got {type(body).__name__}"
        )
    if not isinstance(scene, NumpyScene):
        raise ObstacleError(
            f"scene must be a NumpyScene (NumpyScene.from_scene(scene)), got {type(scene).__name__}"
        )
    if not (isinstance(max_travel, (int, float)) and math.isfinite(max_travel) and max_travel > 0):
        raise ConfigError(f"max_travel must be a finite number of metres > 0, got {max_travel!r}")
    if not (isinstance(margin, (int, float)) and math.isfinite(margin)):
        raise ConfigError(f"margin must be a finite number of metres, got {margin!r}")


class _Paths:
    """Paths ``(P, W = T+1, dof)`` cut into sub-steps as :func:`check_path` cuts them (``steps (P, T)``),
    with each moving sphere's travel and bend bounds per segment (``travel``, ``bend``: ``(Mm, P, T)``)."""

    def __init__(self, body: NumpyBody, paths: np.ndarray, max_travel: float):
        P, W, dof = paths.shape
        self.P, self.W, self.T = P, W, W - 1
        self.paths = paths
        self.delta = paths[:, 1:] - paths[:, :-1]  # (P, T, dof)
        absd = np.abs(self.delta)
        self.absd = absd
        if body.num_moving:
            # Per segment and moving sphere: Σ_j |Δθ_j| lever_mj, summed as segment_steps sums it.
            terms = absd[..., body._sum_order][:, :, None, :] * body._lever_sum
            travel = terms.sum(axis=-1)  # (P, T, Mm)
            self.steps = np.maximum(np.ceil(travel.max(axis=-1, initial=0.0) / max_travel), 1.0)
            self.travel = travel.transpose(2, 0, 1)  # (Mm, P, T)
            # A bound on |d²x/df²| along each segment (f ∈ [0, 1]): the second derivative of a sphere's
            # centre in joints i and j is at most the lever of joint max(i, j), so
            # |x''| ≤ Σ_k lever_k |Δθ_k| (|Δθ_k| + 2 Σ_{i<k} |Δθ_i|).
            w = absd * (2.0 * np.cumsum(absd, axis=-1) - absd)
            self.bend = np.matmul(body._lever_mov, w.reshape(-1, dof).T).reshape(body.num_moving, P, self.T)
        else:
            self.steps = np.ones((P, self.T))
            self.travel = self.bend = np.zeros((0, P, self.T))

    def grid(self, G: int) -> np.ndarray:
        """Round one's configurations ``(P, T·G + 1, dof)``: on each segment the sub-steps ⌊g n / G⌋,
        g = 0 … G−1 (g = 0: the knot), then the last knot. Returns them and the sub-steps ``(P, T, G)``."""
        P, T = self.P, self.T
        sub = (np.arange(G, dtype=np.float64) * self.steps[..., None]) // G
        q = np.empty((P, T * G + 1, self.paths.shape[2]))
        frac = sub / self.steps[..., None]
        q[:, :-1] = (self.paths[:, :-1, None] + frac[..., None] * self.delta[:, :, None]).reshape(
            P, T * G, self.paths.shape[2]
        )
        q[:, -1] = self.paths[:, -1]
        return q, sub

    def configs(self, p: np.ndarray, k: np.ndarray, sub: np.ndarray) -> np.ndarray:
        """Sub-step ``sub`` of segment ``k`` of path ``p``: θ_k + (i / n_k) · Δθ_k, as check_path forms it."""
        frac = sub / self.steps[p, k]
        return self.paths[p, k] + frac[:, None] * self.delta[p, k]


def _grid_size(paths: _Paths) -> int:
    """Grid configurations per segment: about one per :data:`GRID` sub-steps of an average segment."""
    if paths.T == 0:
        return 1
    return max(1, math.ceil(float(paths.steps.sum()) / (paths.steps.size * GRID)))


def _evaluate(body: NumpyBody, scene: NumpyScene, base: float, q: np.ndarray):
    """Configurations ``q (n, dof)`` → ``(centres (3, M, n), per-sphere scene distance (Mm, n) or None,
    body–scene distance (n,))``, in chunks of :data:`CHUNK` configurations (cache-resident temporaries)."""
    n = q.shape[0]
    c = np.empty((3, len(body.radii), n))
    D = np.empty((body.num_moving, n)) if body.num_moving else None
    for lo in range(0, n, CHUNK):
        hi = min(lo + CHUNK, n)
        c[..., lo:hi] = body._fk(q[lo:hi])
        if D is not None:
            D[:, lo:hi] = scene._distances(c[:, body.num_base :, lo:hi], body._r_mov, body._floor_off)
    if D is None:
        return c, None, np.full(n, base)
    d = D.min(axis=0)
    if base < math.inf:
        np.minimum(d, base, out=d)
    return c, D, d


class _RoundOne:
    """The knots and a grid of G sub-steps on every segment: scene distances, collisions, self-collision
    (at the knots, and at the grid of the segments whose knots do not rule it out), and lower bounds of
    both over the sub-steps between grid configurations.

    Configuration j of a path (``(P, J)`` arrays, J = T·G + 1) is sub-step ``lo[j]`` of segment
    ``k[j]`` (j = T·G: the last knot); interval j holds the sub-steps lo[j] < i < hi[j].
    """

    def __init__(self, body: NumpyBody, scene: NumpyScene, base: float, paths: _Paths, margin: float):
        P, W, T = paths.P, paths.W, paths.T
        G = _grid_size(paths)
        J = T * G + 1
        q, sub = paths.grid(G)
        c, D, d = _evaluate(body, scene, base, q.reshape(P * J, -1))
        self.G, self.J = G, J
        self.d = d.reshape(P, J)
        self.bad = self.d <= margin
        self.k = np.minimum(np.arange(J) // G, T)
        hi = np.concatenate([sub[..., 1:], paths.steps[..., None]], axis=-1)  # (P, T, G)
        if D is not None and T:
            self.lb = _interval_bound(paths, c[:, body.num_base :], D, sub, hi)
        else:
            self.lb = np.full((P, T * G), np.inf)
        span = (hi - sub) / paths.steps[..., None]
        self.lo, self.hi = sub.reshape(P, T * G), hi.reshape(P, T * G)
        self.open = (self.hi - self.lo) >= 2.0  # intervals with sub-steps inside
        # Self-collision: segments (ps, ks) whose knots leave it possible, pairs ``pairs``, and per
        # interval of their grid a lower bound over the pairs (``self_lb (len(ps), G)``).
        self.ps = self.ks = np.zeros(0, dtype=np.int64)
        self.pairs = None
        self.self_lb = np.zeros((0, G))
        if not len(body.pairs):
            return
        S = body._self(c.reshape(3, -1, P, J)[..., ::G].reshape(3, -1, P * W)).reshape(-1, P, W)
        self.bad[:, ::G] |= S.min(axis=0) <= 0.0
        if not T:
            return
        rel = np.matmul(body._pair_lever, paths.absd.reshape(-1, body.dof).T).reshape(-1, P, T)
        seg_lb = S[..., :-1] + S[..., 1:]
        seg_lb -= rel
        seg_lb *= 0.5
        flag = seg_lb <= _SLACK
        ps, ks = np.nonzero(flag.any(axis=0))
        if not ps.shape[0]:
            return
        pairs = np.flatnonzero(flag[:, ps, ks].any(axis=1))
        cols = (ps * J + ks * G)[:, None] + np.arange(G + 1)  # the grid of each segment and its end knot
        Sg = body._self(c[..., cols.reshape(-1)], pairs).reshape(-1, ps.shape[0], G + 1)
        self.bad.reshape(-1)[cols] |= Sg.min(axis=0) <= 0.0
        b = Sg[..., :-1] + Sg[..., 1:]
        b -= rel[pairs][:, ps, ks, None] * span[ps, ks]
        b *= 0.5
        np.maximum(b, seg_lb[pairs][:, ps, ks, None], out=b)
        self.ps, self.ks, self.pairs, self.self_lb = ps, ks, pairs, b.min(axis=0)


def _interval_bound(paths: _Paths, cm, D, lo, hi) -> np.ndarray:
    """``(P, T·G)``: a lower bound of the body–scene distance over each interval's sub-steps.

    Per moving sphere: (D(a) + D(b)) / 2 minus the smaller of two bounds on how far the sphere gets from
    the nearer end, half its travel bound over the interval, or half the chord |x(b) − x(a)| plus the most
    the path can bow away from the chord, bend · s² / 8 (s: the interval's fraction of the segment).
    """
    Mm, P = D.shape[0], lo.shape[0]
    D = D.reshape(Mm, P, -1)
    x = cm.reshape(3, Mm, P, -1)
    chord = x[..., 1:] - x[..., :-1]
    chord *= chord
    reach = np.sqrt(chord.sum(axis=0))  # (Mm, P, T·G)
    span = (hi - lo) / paths.steps[..., None]  # (P, T, G)
    reach += (paths.bend[..., None] * (0.25 * span * span)).reshape(Mm, P, -1)
    np.minimum(reach, (paths.travel[..., None] * span).reshape(Mm, P, -1), out=reach)
    b = D[..., :-1] + D[..., 1:]
    b -= reach
    return b.min(axis=0) * 0.5


def _substeps(count: np.ndarray, lo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For runs of ``count`` sub-steps starting after ``lo``: (run index, sub-step) of each."""
    run = np.repeat(np.arange(count.shape[0]), count)
    first = np.cumsum(count) - count
    return run, np.arange(run.shape[0]) - first[run] + lo[run] + 1


def _round_two(body, scene, base, paths: _Paths, r1: _RoundOne, margin, scene_need, self_need):
    """Evaluate every sub-step inside the intervals ``scene_need (P, T·G)`` (scene only) and
    ``self_need (len(r1.ps), G)`` (scene and self-collision). Returns ``(path, k, d, bad)``."""
    pi, ji = np.nonzero(scene_need)
    si, gi = np.nonzero(self_need)
    pi = np.concatenate([pi, r1.ps[si]])
    ji = np.concatenate([ji, r1.ks[si] * r1.G + gi])
    lo, hi = r1.lo[pi, ji], r1.hi[pi, ji]
    count = (hi - lo - 1).astype(np.int64)
    run, sub = _substeps(count, lo)
    p, k = pi[run], r1.k[ji][run]
    c, _, d = _evaluate(body, scene, base, paths.configs(p, k, sub))
    bad = d <= margin
    if si.shape[0]:
        n1 = int(count[: count.shape[0] - si.shape[0]].sum())
        bad[n1:] |= body._self(c[..., n1:], r1.pairs).min(axis=0) <= 0.0
    return p, k, d, bad


def check_paths(
    body: NumpyBody,
    paths: np.ndarray,
    scene: NumpyScene,
    max_travel: float = 0.01,
    margin: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Check joint paths ``paths (P, T+1, dof)`` against one scene and self-collision, densely.

    Returns ``(free (P,) bool, clearance (P,), first_collision (P,) int64)``: for each path the
    ``collision_free``, ``clearance`` and ``first_collision`` of :func:`~kinlearn.collision.check_path`
    (the same sub-steps, self-collision pairs and floor rule; touching counts as a collision; clearance
    +inf for an empty scene). Raises :class:`~kinlearn.errors.ShapeError`,
    :class:`~kinlearn.errors.DTypeError` or :class:`~kinlearn.errors.NonFiniteError` for bad paths,
    :class:`~kinlearn.errors.ConfigError` for a ``max_travel`` that is not a positive number of metres or
    a ``margin`` that is not finite.
    """
    _check_args(body, scene, max_travel, margin)
    arr = _as_joints(paths, body.dof, "joint paths", "P, T+1")
    P, W = arr.shape[:2]
    if P == 0:
        return np.zeros(0, dtype=bool), np.zeros(0), np.zeros(0, dtype=np.int64)
    base = scene._base_distance(body)
    p = _Paths(body, arr, max_travel)
    r1 = _RoundOne(body, scene, base, p, margin)
    clearance = r1.d.min(axis=1)
    first = np.where(r1.bad, r1.k, W).min(axis=1)
    # Intervals that could lower the clearance, or hold a collision before the first one found.
    scene_need = r1.lb < (clearance + _tol(clearance))[:, None]
    scene_need |= (r1.k[:-1] < first[:, None]) & (r1.lb <= margin + _tol(margin))
    scene_need &= r1.open
    self_need = _open(r1, (r1.self_lb <= _SLACK) & (r1.ks < first[r1.ps])[:, None])
    if scene_need.any() or self_need.any():
        p2, k2, d2, bad2 = _round_two(body, scene, base, p, r1, margin, scene_need, self_need)
        np.minimum.at(clearance, p2, d2)
        np.minimum.at(first, p2[bad2], k2[bad2])
    free = first >= W
    return free, clearance, np.where(free, -1, first)


def _open(r1: _RoundOne, need: np.ndarray) -> np.ndarray:
    """``need (len(r1.ps), G)`` restricted to the intervals with sub-steps inside."""
    if not need.shape[0]:
        return need
    j = r1.ks[:, None] * r1.G + np.arange(r1.G)
    return need & r1.open[r1.ps[:, None], j]


def first_free(
    body: NumpyBody,
    paths: np.ndarray,
    scene: NumpyScene,
    order: Sequence[int] | np.ndarray | None = None,
    max_travel: float = 0.01,
    margin: float = 0.0,
) -> int:
    """The index of the first path in ``order`` (default 0, 1, …) that :func:`check_paths` finds
    collision-free, or −1 if none is.

    Cheaper than :func:`check_paths`: no clearance is wanted, so only sub-steps that could collide are
    evaluated, a path with a colliding knot or grid configuration is dropped after the first round, and
    paths are taken in ``order``, the first one alone and then the rest together, stopping as soon as the
    first collision-free one in order is certain. ``order`` must hold distinct indices into ``paths``
    (a :class:`~kinlearn.errors.ConfigError` otherwise); it may leave paths out.
    """
    _check_args(body, scene, max_travel, margin)
    arr = _as_joints(paths, body.dof, "joint paths", "P, T+1")
    P = arr.shape[0]
    if order is None:
        order = np.arange(P)
    else:
        order = np.asarray(order)
        if order.ndim != 1 or (order.size and order.dtype.kind not in "iu"):
            raise ConfigError(f"order must be a 1-D sequence of path indices, got {order!r}")
        if order.size and (
            (order < 0).any() or (order >= P).any() or np.unique(order).shape[0] != order.shape[0]
        ):
            raise ConfigError(f"order must hold distinct path indices in 0…{P - 1}, got {order.tolist()}")
    if order.shape[0] == 0:
        return -1
    base = scene._base_distance(body)
    if base <= margin:  # the fixed spheres touch the scene: every configuration collides
        return -1
    for chunk in (order[:1], order[1:]):
        if chunk.shape[0]:
            found = _first_free_in(body, scene, base, arr[chunk], max_travel, margin)
            if found >= 0:
                return int(chunk[found])
    return -1


def _first_free_in(body, scene, base, arr, max_travel, margin) -> int:
    """Position in ``arr (P, T+1, dof)`` of its first collision-free path, or −1."""
    P = arr.shape[0]
    p = _Paths(body, arr, max_travel)
    r1 = _RoundOne(body, scene, base, p, margin)
    dead = r1.bad.any(axis=1)
    if dead.all():
        return -1
    scene_need = r1.open & (r1.lb <= margin + _tol(margin)) & ~dead[:, None]
    self_need = _open(r1, (r1.self_lb <= _SLACK) & ~dead[r1.ps, None])
    unsure = scene_need.any(axis=1)
    unsure[r1.ps[self_need.any(axis=1)]] = True
    # The first live path that nothing could make collide ends the search; only the unsure paths
    # before it need the second round.
    sure = np.flatnonzero(~dead & ~unsure)
    stop = int(sure[0]) if sure.shape[0] else P
    todo = np.zeros(P, dtype=bool)
    todo[:stop] = unsure[:stop] & ~dead[:stop]
    if todo.any():
        p2, _, _, bad2 = _round_two(
            body, scene, base, p, r1, margin, scene_need & todo[:, None], self_need & todo[r1.ps, None]
        )
        dead[p2[bad2]] = True
        live = np.flatnonzero(~dead[:stop])
        if live.shape[0]:
            return int(live[0])
    return stop if stop < P else -1
