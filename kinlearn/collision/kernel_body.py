"""A :class:`~kinlearn.collision.body.BodySpheres` packed for the compiled kernels (:class:`KernelBody`):
its chain, spheres, lever bounds, the self-collision pairs grouped under a ball per link, and the pairs
proven never to touch within the joint limits (:func:`proven_apart`) left out of paths that stay there."""

from __future__ import annotations

import math
import weakref
from pathlib import Path

import numpy as np
import torch

from ..body.fk import _centres, _chain, _point
from ..body.jit import jit
from ..errors import ConfigError, DTypeError, NonFiniteError, ShapeError
from ..memo import remembered
from .body import BodySpheres

__all__ = ["BOX_SLACK", "KernelBody", "near_pairs", "proven_apart"]

#: Metres of slack in the proofs' bound (the float64 error of a distance is ~1e-15 m).
_SLACK = 1e-9
#: A lower link's spheres are grouped against each higher sphere from this many on (fewer: a looser
#: ball bound costs more evaluations than the pairs it saves).
_GROUP_MIN = 4


@jit
def _within(paths, lo, hi):
    """Whether every value of ``paths (..., dof)`` lies in ``[lo, hi]`` (NaN does not)."""
    dof = lo.shape[0]
    flat = paths.reshape(-1, dof)
    for i in range(flat.shape[0]):
        for j in range(dof):
            v = flat[i, j]
            if not (v >= lo[j] and v <= hi[j]):
                return False
    return True


@jit
def _apart(F, prismatic, a_link, a_folded, b_link, b_folded, gap, rates, lo, hi, max_cells):
    """Whether two spheres (centres fixed in links ``a_link`` and ``b_link``, radii summing to ``gap``)
    stay apart for every configuration in the box ``[lo, hi]``: 1 proven (branch and bound), −1 a
    configuration where they touch found, 0 undecided within ``max_cells`` cells. A cell (centre c,
    half-widths h) holds no contact when d(c) − Σ_j h_j · ``rates[j]`` > 0: ``rates[j]`` bounds how fast
    the pair's distance changes per unit of joint j over all configurations (the verdict's own pair
    rates, 0 for the joints that move both spheres or neither); else the cell is halved along the joint
    that spends most of the bound."""
    dof = lo.shape[0]
    C, H = np.empty((max_cells + 2, dof)), np.empty((max_cells + 2, dof))
    for j in range(dof):
        C[0, j] = 0.5 * (lo[j] + hi[j])
        H[0, j] = 0.5 * (hi[j] - lo[j]) if rates[j] > 0.0 else 0.0
    frames, c, h = np.empty((dof + 1, 3, 4)), np.empty(dof), np.empty(dof)
    n, used = 1, 0
    while n > 0:
        n -= 1
        used += 1
        if used > max_cells:
            return 0
        for j in range(dof):
            c[j], h[j] = C[n, j], H[n, j]
        _chain(c, F, prismatic, frames)
        ax, ay, az = _point(frames, a_link, a_folded)
        bx, by, bz = _point(frames, b_link, b_folded)
        d = math.sqrt((ax - bx) ** 2 + (ay - by) ** 2 + (az - bz) ** 2) - gap
        if d <= 0.0:
            return -1
        spend, best, widest = 0.0, -1, 0.0
        for j in range(dof):
            w = h[j] * rates[j]
            spend += w
            if w > widest:
                widest, best = w, j
        if d - spend > _SLACK:
            continue
        h[best] *= 0.5
        for side in (-1.0, 1.0):
            for j in range(dof):
                C[n, j], H[n, j] = c[j], h[j]
            C[n, best] = c[best] + side * h[best]
            n += 1
    return 1


@jit
def _unpack_body(f, n):
    """A body packed by :attr:`KernelBody.packed` (floats ``f``, integers ``n``) → the verdict's arrays."""
    dof, M, P, G, E, L = n[0], n[1], n[2], n[3], n[4], n[5]
    o = 0
    F = f[o : o + 16 * dof].reshape(dof, 4, 4)
    o += 16 * dof
    folded = f[o : o + 3 * M].reshape(M, 3)
    o += 3 * M
    radii = f[o : o + M]
    o += M
    lever = f[o : o + M * dof].reshape(M, dof)
    o += M * dof
    b_folded = f[o : o + 3 * L].reshape(L, 3)
    o += 3 * L
    b_radius = f[o : o + L]
    o += L
    p_lever = f[o : o + P * dof].reshape(P, dof)
    o += P * dof
    g_lever = f[o : o + G * dof].reshape(G, dof)
    o += G * dof
    m_lever = f[o : o + E * dof].reshape(E, dof)
    o += E * dof
    l_folded = f[o : o + 3 * (dof + 1)].reshape(dof + 1, 3)
    o += 3 * (dof + 1)
    l_radius = f[o : o + dof + 1]
    i = 6
    prismatic = n[i : i + dof] != 0
    i += dof
    link = n[i : i + M]
    i += M
    on_floor = n[i : i + M] != 0
    i += M
    pairs = n[i : i + 2 * P].reshape(P, 2)
    i += 2 * P
    g_sphere = n[i : i + G]
    i += G
    g_ball = n[i : i + G]
    i += G
    g_start = n[i : i + G + 1]
    i += G + 1
    g_members = n[i : i + E]
    i += E
    b_link = n[i : i + L]
    i += L
    l_start = n[i : i + dof + 2]
    return (
        F, prismatic, link, folded, radii, on_floor, pairs, lever,
        g_sphere, g_ball, g_start, g_members, b_link, b_folded, b_radius, p_lever, g_lever, m_lever,
        l_start, l_folded, l_radius,
    )  # fmt: skip


class KernelBody:
    """A :class:`BodySpheres` packed for the kernels (float64 arrays): the canonical fixed transforms
    ``F (dof, 4, 4)`` of its chain, each sphere's link and centre in its link's canonical frame, radii,
    the spheres the floor applies to, self-collision pairs and lever bounds."""

    @classmethod
    def of(cls, body: BodySpheres) -> KernelBody:
        """The packed ``body``, made on the first call for that body object and kept while it lives
        (a body's buffers are not changed after it is made)."""
        hit = _BODIES.get(body) if isinstance(body, BodySpheres) else None
        if hit is None:
            hit = cls(body)
            _BODIES[body] = hit
        return hit

    def __init__(self, body: BodySpheres):
        if not isinstance(body, BodySpheres):
            raise ConfigError(f"KernelBody needs a BodySpheres, got {type(body).__name__}")
        from ..body.kinematics import _z_to_axis
        from .body import _axis_distances

        robot = body.robot
        self.robot, self.name, self.dof = robot, body.name, robot.dof
        #: How far from the base's origin the body can reach (:attr:`BodySpheres.reach`, m): the obstacle
        #: network reads the primitives within it (:meth:`KernelScene.model_rows`).
        self.reach = body.reach
        local = body.local.detach().cpu().double().numpy()
        self.link = np.ascontiguousarray(body.link.cpu().numpy().astype(np.int64))
        folded = local.copy()
        for m, k in enumerate(self.link):
            if k > 0:
                folded[m] = _z_to_axis(robot.joints[k - 1].axis).T @ local[m]
        self.folded = np.ascontiguousarray(folded)
        self.F = np.ascontiguousarray(np.asarray(body._kin.F[: robot.dof], dtype=np.float64))
        self.prismatic = np.array([j.kind == "prismatic" for j in robot.joints], dtype=np.bool_)
        self.radii = np.ascontiguousarray(body.radii.detach().cpu().double().numpy())
        self.on_floor = np.ascontiguousarray(body.floor_mask.cpu().numpy().astype(np.bool_))
        self.pairs = np.ascontiguousarray(body.pairs.cpu().numpy().astype(np.int64).reshape(-1, 2))
        self.lever = np.ascontiguousarray(body.lever.detach().cpu().double().numpy())
        self._packed = None
        # A ball per link around its spheres (centre: their mean, in the link's frame; the spheres are
        # sorted by link, those of link l are l_start[l] to l_start[l + 1]): the probe's broad phase, and
        # the bound of a group of pairs with that link's spheres.
        self.l_start = np.ascontiguousarray(
            np.searchsorted(self.link, np.arange(self.dof + 2)).astype(np.int64)
        )
        self.l_folded = np.zeros((self.dof + 1, 3))
        self.l_radius = np.zeros(self.dof + 1)
        for lk in range(self.dof + 1):
            a, b = self.l_start[lk], self.l_start[lk + 1]
            if b > a:
                self.l_folded[lk] = self.folded[a:b].mean(axis=0)
                self.l_radius[lk] = float(
                    (np.linalg.norm(self.folded[a:b] - self.l_folded[lk], axis=1) + self.radii[a:b]).max()
                )
        self._axis = _axis_distances(robot, self.link, local)
        # The joint box the pairs below are proven apart in: the robot's limits, widened by BOX_SLACK.
        self.box = (
            np.asarray(robot.lower, dtype=np.float64) - BOX_SLACK,
            np.asarray(robot.upper, dtype=np.float64) + BOX_SLACK,
        )
        self._apart = None
        self._packed_within = None
        self._boxed = None

    def _items(self, pairs: np.ndarray) -> dict:
        """The verdict's self-collision items of ``pairs``, by name: a sphere's pairs with the
        spheres of one lower link (one that has at least _GROUP_MIN) go as one item, bounded by a ball
        around that link's spheres (centre: their mean, in its frame); the other pairs one by one."""
        la, lb = self.link[pairs[:, 0]], self.link[pairs[:, 1]]
        upper = np.where(la > lb, pairs[:, 0], pairs[:, 1])  # the sphere on the higher link
        lower = np.where(la > lb, pairs[:, 1], pairs[:, 0])
        counts = np.bincount(self.link, minlength=self.dof + 1)
        grouped = counts[self.link[lower]] >= _GROUP_MIN
        ball_links = np.unique(self.link[lower[grouped]])
        index = {int(l): b for b, l in enumerate(ball_links)}
        up, low = upper[grouped], lower[grouped]
        key = up * (self.dof + 1) + self.link[low]
        order = np.argsort(key, kind="stable")
        keys, starts = np.unique(key[order], return_index=True)
        it = {
            "pairs": np.ascontiguousarray(pairs[~grouped]),
            "b_link": np.ascontiguousarray(ball_links.astype(np.int64)),
            "b_folded": np.ascontiguousarray(self.l_folded[ball_links].reshape(-1, 3)),
            "b_radius": np.ascontiguousarray(self.l_radius[ball_links]),
            "g_sphere": np.ascontiguousarray((keys // (self.dof + 1)).astype(np.int64)),
            "g_ball": np.array([index[int(l)] for l in keys % (self.dof + 1)], dtype=np.int64),
            "g_start": np.ascontiguousarray(np.append(starts, len(order)).astype(np.int64)),
            "g_members": np.ascontiguousarray(low[order].astype(np.int64)),
        }
        # How fast each self-collision item can close, per radian of each joint between its links: the
        # smaller of the upper sphere's lever and the lower sphere's distance from the joint's axis
        # (:func:`~kinlearn.collision.body._axis_distances`); a group's, the largest over its members.
        g_lever = np.zeros((len(it["g_sphere"]), self.dof))
        m_lever = np.zeros((len(it["g_members"]), self.dof))
        for g, x in enumerate(it["g_sphere"]):
            span = slice(it["g_start"][g], it["g_start"][g + 1])
            members = it["g_members"][span]
            m_lever[span] = self._item_lever(np.stack([np.full(len(members), x), members], axis=1))
            g_lever[g] = m_lever[span].max(axis=0)
        it["pair_lever"] = np.ascontiguousarray(self._item_lever(it["pairs"]))
        it["group_lever"] = np.ascontiguousarray(g_lever)
        it["member_lever"] = np.ascontiguousarray(m_lever)
        return it

    def _item_lever(self, pairs: np.ndarray) -> np.ndarray:
        """``(P, dof)``: per pair and joint, min(lever of its upper sphere, axis distance of its lower one)
        for the joints between their links (those that move one and not the other), 0 for the rest."""
        la, lb = self.link[pairs[:, 0]], self.link[pairs[:, 1]]
        up = np.where(la > lb, pairs[:, 0], pairs[:, 1])
        low = np.where(la > lb, pairs[:, 1], pairs[:, 0])
        j = np.arange(self.dof)
        between = (j[None] >= self.link[low][:, None]) & (j[None] < self.link[up][:, None])
        return np.where(between, np.minimum(self.lever[up], self._axis[low]), 0.0)

    @property
    def apart(self) -> np.ndarray:
        """``(P,)`` bool: the self-collision pairs proven never to touch while every joint is in
        :attr:`box` (see :func:`proven_apart`); made on first use, kept per body's numbers."""
        if self._apart is None:
            self._apart = proven_apart(self)
        return self._apart

    @property
    def num_spheres(self) -> int:
        return int(self.radii.shape[0])

    def fk_args(self) -> tuple:
        return self.F, self.prismatic, self.link, self.folded

    def args(self) -> tuple:
        return self.F, self.prismatic, self.link, self.folded, self.radii, self.on_floor, self.pairs

    @property
    def packed(self) -> tuple[np.ndarray, np.ndarray]:
        """The verdict's arrays in two buffers (floats, integers), for the packed entry points: every
        self-collision pair, right for any path."""
        if self._packed is None:
            self._packed = self._pack(self._items(self.pairs))
        return self._packed

    @property
    def packed_within(self) -> tuple[np.ndarray, np.ndarray]:
        """:attr:`packed` without the pairs proven apart (:attr:`apart`): the same verdicts, for paths
        whose every knot lies in :attr:`box` (the box is convex: so does every configuration between)."""
        if self._packed_within is None:
            self._packed_within = self._pack(self._items(self.pairs[~self.apart]))
        return self._packed_within

    def packing_of(self, paths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The packing for ``paths (..., dof)`` (float64, C-contiguous): :attr:`packed_within` when every
        knot lies in :attr:`box`, else :attr:`packed`. Paths between points that all lie in the box stay
        in it (the box is convex): pass those points to choose for them all."""
        if _within(paths, *self.box):
            return self.packed_within
        return self.packed

    @property
    def boxed(self) -> tuple[np.ndarray, ...]:
        """What :func:`first_free_boxed` takes of the body: :attr:`box`, :attr:`packed_within`,
        :attr:`packed` (made once)."""
        if self._boxed is None:
            self._boxed = (*self.box, *self.packed_within, *self.packed)
        return self._boxed

    def _pack(self, it: dict) -> tuple[np.ndarray, np.ndarray]:
        """The body and self-collision items ``it`` (:meth:`_items`) in two buffers (:func:`_unpack_body`)."""
        M, P, G = len(self.radii), len(it["pairs"]), len(it["g_sphere"])
        E, L = len(it["g_members"]), len(it["b_link"])
        f = np.concatenate(
            [
                self.F.ravel(),
                self.folded.ravel(),
                self.radii,
                self.lever.ravel(),
                it["b_folded"].ravel(),
                it["b_radius"],
                it["pair_lever"].ravel(),
                it["group_lever"].ravel(),
                it["member_lever"].ravel(),
                self.l_folded.ravel(),
                self.l_radius,
            ]
        )
        n = np.concatenate(
            [
                [self.dof, M, P, G, E, L],
                self.prismatic.astype(np.int64),
                self.link,
                self.on_floor.astype(np.int64),
                it["pairs"].ravel(),
                it["g_sphere"],
                it["g_ball"],
                it["g_start"],
                it["g_members"],
                it["b_link"],
                self.l_start,
            ]
        ).astype(np.int64)
        return np.ascontiguousarray(f), np.ascontiguousarray(n)

    def __repr__(self) -> str:
        return f"KernelBody(robot={self.robot.name!r}, set={self.name!r}, spheres={self.num_spheres}, pairs={len(self.pairs)})"


#: Radians the box self-collision pairs are proven apart in reaches past each joint limit (a planner's
#: paths keep within ``LIMIT_TOLERANCE``, 1e-6 rad, of them).
BOX_SLACK = 1e-3
#: Configurations (uniform in the box, seeded) every pair is first tried at: one that touches at any
#: needs no proof. Then the most cells one pair's proof may split into before the pair is kept as
#: undecided (fewer cells prove fewer pairs apart; more take longer for a few more).
_APART_SAMPLES, _APART_CELLS = 4096, 20000
#: Proofs made, by the numbers they depend on (bodies alike share them).
_APART: dict[bytes, np.ndarray] = {}


def proven_apart(body: KernelBody) -> np.ndarray:
    """``(P,)`` bool: which of ``body``'s self-collision pairs are proven never to touch while every joint
    lies in ``body.box`` (an SRDF's "never in collision" pairs, proven rather than sampled).

    Each pair is first looked at in :data:`_APART_SAMPLES` configurations; one that touches in any is
    kept. The others go to a branch and bound over the box (:func:`_apart`) bounded by the verdict's own
    rates (how fast the pair's distance can change per radian of each joint between their links), so a
    pair is dropped only where no configuration of the box brings it to contact; one undecided within
    :data:`_APART_CELLS` cells is kept. A pair so dropped changes no verdict of a path inside the box:
    its distance there is > 0 at every configuration."""
    lo, hi = body.box
    P = len(body.pairs)
    if P == 0 or not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        return np.zeros(P, dtype=bool)
    key = b"".join(
        np.ascontiguousarray(a).tobytes()
        for a in (body.F, body.prismatic, body.link, body.folded, body.radii, body.pairs, body._axis, lo, hi)
    )
    hit = _APART.get(key)
    if hit is None:
        parts = (key, _APART_SAMPLES, _APART_CELLS)  # every process proves the same: kept on disk

        def prove() -> np.ndarray:
            return _prove(body, lo, hi)

        hit = _APART[key] = remembered("pairs-apart", parts, prove, dtype=bool, shape=(P,), code=_CODE)
    return hit


#: The modules whose code the proof runs (a change to them is a new proof).
_CODE = (__file__, str(Path(__file__).parents[1] / "body" / "fk.py"))


def _prove(body: KernelBody, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """:func:`proven_apart`'s work: the samples, then the branch and bound of each pair none touches."""
    P = len(body.pairs)
    qs = lo + (hi - lo) * np.random.default_rng(0).random((_APART_SAMPLES, body.dof))
    # touching: a distance ≤ 0, i.e. below the smallest positive float
    touch = _near_pairs(_centres(qs, *body.fk_args()), body.radii, body.pairs, np.nextafter(0.0, 1.0)).any(0)
    rates = np.ascontiguousarray(body._item_lever(body.pairs))
    hit = np.zeros(P, dtype=bool)
    for p in np.flatnonzero(~touch):
        a, b = body.pairs[p]
        found = _apart(
            body.F, body.prismatic, body.link[a], body.folded[a], body.link[b], body.folded[b],
            body.radii[a] + body.radii[b], rates[p], lo, hi, _APART_CELLS,
        )  # fmt: skip
        hit[p] = found == 1
    return hit


#: Bodies packed by :meth:`KernelBody.of`, dropped with their body.
_BODIES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


@jit
def _all_finite(a):
    for v in a.flat:
        if not math.isfinite(v):
            return False
    return True


@jit
def _near_pairs(c, radii, pairs, cut):
    """``(B, P)`` bool: pair k of configuration b closer than ``cut`` (signed)."""
    B, P = c.shape[0], pairs.shape[0]
    out = np.empty((B, P), dtype=np.bool_)
    for b in range(B):
        for k in range(P):
            i, j = pairs[k, 0], pairs[k, 1]
            dx, dy, dz = c[b, i, 0] - c[b, j, 0], c[b, i, 1] - c[b, j, 1], c[b, i, 2] - c[b, j, 2]
            out[b, k] = math.sqrt(dx * dx + dy * dy + dz * dz) - radii[i] - radii[j] < cut
    return out


def near_pairs(centres, radii, pairs, cut: float) -> tuple[np.ndarray, np.ndarray]:
    """The sphere pairs closer than ``cut`` (m, signed: centre distance less both radii): for centres
    ``(B, M, 3)``, radii ``(M,)`` and pairs ``(P, 2)``, the configuration and pair indices ``(A,)`` of each
    such pair, in order. A broad phase for losses that a pair adds to only within a margin."""
    c = np.ascontiguousarray(np.asarray(centres, dtype=np.float64))
    r = np.ascontiguousarray(np.asarray(radii, dtype=np.float64))
    pr = np.ascontiguousarray(np.asarray(pairs, dtype=np.int64))
    if c.ndim != 3 or c.shape[-1] != 3 or r.shape != (c.shape[1],) or pr.ndim != 2 or pr.shape[-1] != 2:
        raise ShapeError(
            f"near_pairs takes centres (B, M, 3), radii (M,), pairs (P, 2); got {c.shape}, {r.shape}, {pr.shape}"
        )
    b, k = np.nonzero(_near_pairs(c, r, pr, float(cut)))
    return b.astype(np.int64), k.astype(np.int64)


def _joints(x, dof: int, what: str, ndim: int, finite: bool = True) -> np.ndarray:
    """``x`` as a C-contiguous float64 array of ``ndim`` dimensions, the last of size ``dof``; its values
    checked finite unless ``finite=False`` (the caller's kernel checks them)."""
    if type(x) is np.ndarray and x.dtype == np.float64 and x.ndim == ndim and x.flags.c_contiguous:
        if x.shape[-1] != dof:  # the common case (a planner's own arrays): no conversion at all
            raise ShapeError(f"{what} must have {ndim} dimensions, the last of size {dof}; got {x.shape}")
        if finite and not _all_finite(x):
            raise NonFiniteError(f"{what} holds {int((~np.isfinite(x)).sum())} NaN/inf value(s)")
        return x
    if isinstance(x, torch.Tensor):
        x = x.detach().cpu().numpy()
    a = np.asarray(x)
    if a.dtype.kind != "f":
        raise DTypeError(f"{what} must hold real floating-point numbers, got dtype {a.dtype}")
    if a.ndim != ndim or a.shape[-1] != dof:
        raise ShapeError(f"{what} must have {ndim} dimensions, the last of size {dof}; got {a.shape}")
    a = np.ascontiguousarray(a, dtype=np.float64)
    if not _all_finite(a):
        raise NonFiniteError(f"{what} holds {int((~np.isfinite(a)).sum())} NaN/inf value(s)")
    return a
