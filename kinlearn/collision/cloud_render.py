"""Scenes of primitives rendered as point clouds, as a sensor would see them: for benchmarks, tests and
trying the cloud pipeline without a camera.

- :func:`surface_points`: every primitive's surface sampled on a grid of ``spacing`` (m), with Gaussian
  noise of ``noise`` (m, per axis): a fused multi-view scan, nothing occluded.
- :class:`DepthCamera`: a pinhole camera at one viewpoint, rays cast through its ``width`` × ``height``
  pixels against the primitives, the floor and optional extra spheres (the robot's own body), the nearest
  hit per pixel kept, with Gaussian noise of ``noise`` along the ray: what one depth image sees, the
  hidden sides of every obstacle missing. Floor hits are dropped (a floor is given as a plane).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import ObstacleError
from .geometry import Box, Cylinder, Sphere

__all__ = ["DepthCamera", "surface_points"]


def _grid(lo: float, hi: float, spacing: float) -> np.ndarray:
    return np.linspace(lo, hi, max(2, math.ceil((hi - lo) / spacing) + 1))


def _box_surface(p: Box, spacing: float) -> np.ndarray:
    h = np.asarray(p.half_extents)
    faces = []
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3
        u, v = np.meshgrid(_grid(-h[b], h[b], spacing), _grid(-h[c], h[c], spacing), indexing="ij")
        for sign in (-1.0, 1.0):
            f = np.empty((u.size, 3))
            f[:, a], f[:, b], f[:, c] = sign * h[a], u.ravel(), v.ravel()
            faces.append(f)
    local = np.concatenate(faces)
    return local @ np.asarray(p.rotation).reshape(3, 3).T + np.asarray(p.centre)


def _cylinder_surface(p: Cylinder, spacing: float) -> np.ndarray:
    r, hl = p.radius, p.half_length
    n_theta = max(8, math.ceil(2 * math.pi * r / spacing))
    theta = np.linspace(0.0, 2 * math.pi, n_theta, endpoint=False)
    z = _grid(-hl, hl, spacing)
    tt, zz = np.meshgrid(theta, z, indexing="ij")
    side = np.stack([r * np.cos(tt).ravel(), r * np.sin(tt).ravel(), zz.ravel()], axis=1)
    caps = [np.zeros((1, 3))]
    for rho in _grid(0.0, r, spacing)[1:]:
        n = max(6, math.ceil(2 * math.pi * rho / spacing))
        a = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
        caps.append(np.stack([rho * np.cos(a), rho * np.sin(a), np.zeros(n)], axis=1))
    disc = np.concatenate(caps)
    lift = np.array([0.0, 0.0, hl])
    top, bottom = disc + lift, disc - lift
    local = np.concatenate([side, top, bottom])
    return local @ np.asarray(p.rotation).reshape(3, 3).T + np.asarray(p.centre)


def _sphere_surface(p: Sphere, spacing: float) -> np.ndarray:
    n = max(12, math.ceil(4 * math.pi * p.radius**2 / spacing**2 * 1.2))
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = math.pi * (1 + 5**0.5) * i
    d = np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=1)
    return np.asarray(p.centre) + p.radius * d


def surface_points(scene, spacing: float = 0.01, noise: float = 0.002, seed: int = 0) -> np.ndarray:
    """``(N, 3)``: the surfaces of an unbatched scene's primitives (not its floor) sampled on grids of at most
    ``spacing`` (m) between neighbours, each point moved by Gaussian noise of ``noise`` (m) per axis."""
    parts = []
    for p in scene.primitives():
        if isinstance(p, Box):
            parts.append(_box_surface(p, spacing))
        elif isinstance(p, Cylinder):
            parts.append(_cylinder_surface(p, spacing))
        elif isinstance(p, Sphere):
            parts.append(_sphere_surface(p, spacing))
    if not parts:
        raise ObstacleError("the scene has no primitive to sample (a floor alone is a plane)")
    pts = np.concatenate(parts)
    return pts + np.random.default_rng(seed).normal(0.0, noise, pts.shape)


@dataclass(frozen=True)
class DepthCamera:
    """A pinhole depth camera at ``position`` (m, the base frame) looking at ``target``, ``width`` ×
    ``height`` pixels over a horizontal field of view of ``fov`` degrees, seeing from ``near`` to ``far``
    (m), with Gaussian depth noise of ``noise`` (m) along each ray."""

    position: tuple[float, float, float]
    target: tuple[float, float, float]
    width: int = 320
    height: int = 240
    fov: float = 75.0
    near: float = 0.1
    far: float = 4.0
    noise: float = 0.002

    def pose(self) -> np.ndarray:
        """The camera's pose in the base frame, 4 × 4: its axes x right, y down, z forward (the optical
        frame of OpenCV and ROS), its origin at ``position``."""
        o, t = np.asarray(self.position, dtype=float), np.asarray(self.target, dtype=float)
        fwd = (t - o) / np.linalg.norm(t - o)
        right = np.cross(fwd, np.array([0.0, 0.0, 1.0]))
        if np.linalg.norm(right) < 1e-9:
            right = np.array([0.0, -1.0, 0.0])
        right /= np.linalg.norm(right)
        T = np.eye(4)
        T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = right, np.cross(fwd, right), fwd, o
        return T

    def focal(self) -> float:
        """The focal length in pixels: ``width`` pixels span ``fov`` degrees."""
        return 0.5 * self.width / math.tan(math.radians(self.fov) / 2)

    def rays(self) -> np.ndarray:
        """Unit ray directions ``(height · width, 3)`` in the base frame."""
        T = self.pose()
        right, down, fwd = T[:3, 0], T[:3, 1], T[:3, 2]
        f = self.focal()
        u = np.arange(self.width) + 0.5 - self.width / 2
        v = np.arange(self.height) + 0.5 - self.height / 2
        uu, vv = np.meshgrid(u, v)
        d = fwd * f + uu.reshape(-1, 1) * right + vv.reshape(-1, 1) * down
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def points(self, scene, spheres: np.ndarray | None = None, seed: int = 0) -> np.ndarray:
        """``(N, 3)``: one point per pixel whose ray hits a primitive of the unbatched ``scene`` or one of
        ``spheres (K, 4)`` (x, y, z, r; the robot's body, say) nearer than the floor and within range."""
        o = np.asarray(self.position, dtype=float)
        D = self.rays()
        t = self.first_hits(scene, D, spheres)
        seen = np.isfinite(t) & (t >= self.near) & (t <= self.far)
        rng = np.random.default_rng(seed)
        depth = t[seen] + rng.normal(0.0, self.noise, int(seen.sum()))
        return o + D[seen] * depth[:, None]

    def first_hits(self, scene, directions, spheres: np.ndarray | None = None) -> np.ndarray:
        """``(K,)``: how far (m) the ray from the camera along each unit vector of ``directions (K, 3)`` (the
        base frame) runs before it meets a primitive of the unbatched ``scene`` or one of ``spheres (K', 4)``;
        inf where it meets none, or meets the floor first."""
        o = np.asarray(self.position, dtype=float)
        D = np.asarray(directions, dtype=float).reshape(-1, 3)
        t = np.full(D.shape[0], np.inf)
        extra = [] if spheres is None else [Sphere(tuple(s[:3]), float(s[3])) for s in np.asarray(spheres)]
        for p in scene.primitives() + extra:
            if isinstance(p, Sphere):
                t = np.minimum(t, _hit_sphere(o, D, np.asarray(p.centre), p.radius))
            elif isinstance(p, Box):
                t = np.minimum(t, _hit_box(o, D, p))
            elif isinstance(p, Cylinder):
                t = np.minimum(t, _hit_cylinder(o, D, p))
        if scene.floor is not None:
            with np.errstate(divide="ignore", invalid="ignore"):
                tf = (float(scene.floor) - o[2]) / D[:, 2]
            tf = np.where((tf > 0) & np.isfinite(tf), tf, np.inf)
            t = np.where(tf < t, np.inf, t)  # the floor hides what lies beyond it; its own hits dropped
        return t

    def sees(self, scene, points, spheres: np.ndarray | None = None, tolerance: float = 0.01) -> np.ndarray:
        """``(K,)`` bool: whether the camera sees each of ``points (K, 3)`` (on the surfaces of ``scene``, say):
        in its image and range, and its ray meets nothing (``scene``'s primitives, ``spheres``, the floor)
        more than ``tolerance`` (m) before it."""
        T = self.pose()
        v = np.asarray(points, dtype=float).reshape(-1, 3) - T[:3, 3]
        dist = np.linalg.norm(v, axis=1)
        local = v @ T[:3, :3]  # x right, y down, z forward
        f = self.focal()
        with np.errstate(divide="ignore", invalid="ignore"):
            u, w = f * local[:, 0] / local[:, 2], f * local[:, 1] / local[:, 2]
        framed = (local[:, 2] > 0) & (np.abs(u) <= self.width / 2) & (np.abs(w) <= self.height / 2)
        t = self.first_hits(scene, v / np.maximum(dist, 1e-12)[:, None], spheres)
        return framed & (dist >= self.near) & (dist <= self.far) & ~(t < dist - tolerance)


def _hit_sphere(o, D, c, r) -> np.ndarray:
    oc = o - c
    b = D @ oc
    disc = b * b - (oc @ oc - r * r)
    with np.errstate(invalid="ignore"):
        t = -b - np.sqrt(disc)
    return np.where((disc >= 0) & (t > 0), t, np.inf)


def _hit_box(o, D, p: Box) -> np.ndarray:
    R = np.asarray(p.rotation).reshape(3, 3)
    ol, Dl = R.T @ (o - np.asarray(p.centre)), D @ R
    h = np.asarray(p.half_extents)
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (-h - ol) / Dl, (h - ol) / Dl
    lo = np.where(np.isnan(t1), -np.inf, np.minimum(t1, t2)).max(axis=1)
    hi = np.where(np.isnan(t1), np.inf, np.maximum(t1, t2)).min(axis=1)
    return np.where((hi >= np.maximum(lo, 0)) & (lo > 0), lo, np.inf)


def _hit_cylinder(o, D, p: Cylinder) -> np.ndarray:
    R = np.asarray(p.rotation).reshape(3, 3)
    ol, Dl = R.T @ (o - np.asarray(p.centre)), D @ R
    r, hl = p.radius, p.half_length
    a = Dl[:, 0] ** 2 + Dl[:, 1] ** 2
    b = ol[0] * Dl[:, 0] + ol[1] * Dl[:, 1]
    c = ol[0] ** 2 + ol[1] ** 2 - r * r
    disc = b * b - a * c
    with np.errstate(divide="ignore", invalid="ignore"):
        ts = (-b - np.sqrt(disc)) / a
        zs = ol[2] + ts * Dl[:, 2]
        side = np.where((disc >= 0) & (ts > 0) & (np.abs(zs) <= hl), ts, np.inf)
        best = side
        for cap in (-hl, hl):
            tc = (cap - ol[2]) / Dl[:, 2]
            x, y = ol[0] + tc * Dl[:, 0], ol[1] + tc * Dl[:, 1]
            best = np.minimum(best, np.where((tc > 0) & (x * x + y * y <= r * r), tc, np.inf))
    return best
