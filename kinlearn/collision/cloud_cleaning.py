"""Cleaning a sensed cloud before it becomes obstacles: the steps :class:`Cleaning` names, applied by
:func:`clean_points` in this order: dropping points beyond the robot's reach, dropping those on the
robot's own body at its configuration (self-filtering), voxel down-sampling, and radius or statistical
outlier removal. The neighbourhood searches are compiled kernels over points sorted by cell. Bad settings
or a cloud cleaned away raise :class:`~kinlearn.errors.PointCloudError`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
import torch

from ..body.jit import jit
from ..errors import PointCloudError

__all__ = ["Cleaning", "clean_points"]


@dataclass(frozen=True)
class Cleaning:
    """Optional steps that clean a cloud before it becomes obstacles (:func:`clean_points`), applied in
    this order:

    - ``reach``: drop points farther than this (m) from the base's origin, less their radius (none of
      those can touch the robot: with a body, its :attr:`~kinlearn.collision.BodySpheres.reach` is taken
      when this is None). Keeps the grid small where a camera sees the room behind the robot.
    - self-filtering (given a body and its configuration to :func:`clean_points`): drop every point whose
      ball comes within ``self_margin`` (m) of one of the body's spheres there, the robot seeing itself;
      at each further configuration given (a goal vouched for), within ``vouch_margin``: there the points
      are the obstacles' own surface, which the margin's shell would hide from the approach (a sensor's
      noise, not its view of the robot).
    - ``voxel``: one point per occupied cube of this edge (m), their centroid. The grid is an occupancy
      grid, so this mainly saves reading time; a voxel larger than the grid's resolution moves the
      surface by up to half its diagonal (give ``radius`` room for it).
    - ``outliers``: ``"radius"`` drops points with fewer than ``min_neighbours`` others within
      ``outlier_radius`` (m); ``"statistical"`` drops points whose mean distance to their ``neighbours``
      nearest (searched within the 27 cells of edge ``outlier_radius`` around them; those not found count
      as ``outlier_radius``) exceeds the cloud's mean by ``std_ratio`` standard deviations. Speckle a
      depth camera leaves at depth edges; each removed point is an obstacle less, so keep it off where a
      thin real obstacle is sampled sparsely.
    """

    reach: float | None = None
    #: A point's ball already reaches its radius beyond the body, which covers a sensor's noise about the
    #: robot's own surface; a wider shell hides the obstacles beside the start, and the first motion away
    #: from them may cut into what it hid. On the tuning problems' surface clouds (seeds 3004–3010, 140 per
    #: arm, 2 mm noise) 5 mm solved 99.3% (panda) and 97.9% (ur5) with no plan colliding with the true
    #: obstacles; 1 cm solved 98.6% and 96.4% with 1 and 2 colliding next to the start.
    self_margin: float = 0.005
    #: On the tuning problems' surface clouds (seeds 3004–3010, 140 per arm, 2 mm noise, the goal vouched
    #: for) 4 mm left no plan colliding with the true obstacles and solved 99.3% (panda) and 97.1% (ur5 with
    #: its gripper); 1 cm let 3 plans per arm collide and solved 97.1% and 96.4%; 0 solved 99.3% and 95.7%.
    vouch_margin: float = 0.004
    voxel: float | None = None
    outliers: Literal["none", "radius", "statistical"] = "none"
    outlier_radius: float = 0.03
    min_neighbours: int = 3
    neighbours: int = 8
    std_ratio: float = 2.0

    def __post_init__(self):
        for name in ("reach", "voxel"):
            v = getattr(self, name)
            if v is not None and not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise PointCloudError(f"Cleaning.{name} must be None or a number of metres > 0, got {v!r}")
        for name in ("self_margin", "vouch_margin", "outlier_radius", "std_ratio"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise PointCloudError(f"Cleaning.{name} must be a finite number >= 0, got {v!r}")
        if self.outliers not in ("none", "radius", "statistical"):
            raise PointCloudError(
                f"Cleaning.outliers must be 'none', 'radius' or 'statistical', got {self.outliers!r}"
            )
        for name in ("min_neighbours", "neighbours"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise PointCloudError(f"Cleaning.{name} must be an integer >= 1, got {v!r}")
        if self.outliers != "none" and not self.outlier_radius > 0:
            raise PointCloudError("Cleaning.outlier_radius must be > 0 to remove outliers")


def body_of(body):
    """A :class:`~kinlearn.collision.BodySpheres`, or the ``body`` of a planner."""
    from .body import BodySpheres

    if isinstance(body, BodySpheres):
        return body
    inner = getattr(body, "body", None)
    if isinstance(inner, BodySpheres):
        return inner
    raise PointCloudError(
        f"self-filtering takes the robot's BodySpheres (or a planner) and its joints, got {type(body).__name__}"
    )


def clean_points(
    points: np.ndarray, radius: float, cleaning: Cleaning | None = None, self_filter: tuple | None = None
) -> np.ndarray:
    """The points ``(N, 3)`` (base frame, checked) after the steps of ``cleaning`` (see :class:`Cleaning`);
    ``self_filter``: ``(body, q)``, a :class:`~kinlearn.collision.BodySpheres` (or a planner) and the
    robot's joints ``(dof,)`` when the cloud was taken: the points on its own body are dropped
    (``cleaning.self_margin``); ``q (K, dof)``: its first row where the robot stands, each further row a
    configuration vouched for (a goal), whose body drops the points it touches too
    (``cleaning.vouch_margin``: those points are then no obstacle anywhere).
    :class:`PointCloudError` if nothing is left."""
    cleaning = cleaning or Cleaning()
    pts = points
    reach = cleaning.reach
    centres = None
    if self_filter is not None:
        try:
            body, q = self_filter
        except (TypeError, ValueError) as exc:
            raise PointCloudError("self_filter must be a pair (body, joints)") from exc
        body = body_of(body)
        q = torch.as_tensor(np.asarray(q, dtype=np.float64)).to(body.radii)
        dof = body.robot.dof
        if q.shape[-1:] != (dof,) or q.ndim not in (1, 2) or q.numel() == 0:
            raise PointCloudError(
                f"self_filter's joints must have shape ({dof},) or (K, {dof}), got {tuple(q.shape)}"
            )
        with torch.no_grad():
            q = q.reshape(-1, dof)
            centres = body(q).detach().cpu().double().numpy().reshape(-1, 3)
            r = body.radii.detach().cpu().double().numpy()
            # the first configuration's spheres widened by the robot's margin, the vouched ones' by theirs
            radii = np.concatenate(
                [r + cleaning.self_margin] + [r + cleaning.vouch_margin] * (q.shape[0] - 1)
            )
        if reach is None:
            reach = body.reach + cleaning.self_margin
    if reach is not None:
        pts = pts[np.linalg.norm(pts, axis=1) - radius <= reach]
    if centres is not None and len(pts):
        keep = np.empty(len(pts), dtype=np.bool_)
        _outside_spheres(pts, np.ascontiguousarray(centres), radii + radius, keep)
        pts = pts[keep]
    if cleaning.voxel is not None and len(pts):
        pts = _voxel_centroids(pts, cleaning.voxel)
    if cleaning.outliers != "none" and len(pts):
        keep = _inliers(pts, cleaning)
        pts = pts[keep]
    if len(pts) == 0:
        raise PointCloudError("no point is left after cleaning (reach, self-filtering, outliers)")
    return np.ascontiguousarray(pts)


@jit
def _outside_spheres(points, centres, reach, keep):
    """``keep[i]``: point i lies farther than ``reach[m]`` from every centre m (a point outside the box that
    holds the spheres, at once)."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for m in range(centres.shape[0]):
        for a in range(3):
            lo[a] = min(lo[a], centres[m, a] - reach[m])
            hi[a] = max(hi[a], centres[m, a] + reach[m])
    for i in range(points.shape[0]):
        if not (
            lo[0] <= points[i, 0] <= hi[0]
            and lo[1] <= points[i, 1] <= hi[1]
            and lo[2] <= points[i, 2] <= hi[2]
        ):
            keep[i] = True
            continue
        ok = True
        for m in range(centres.shape[0]):
            dx = points[i, 0] - centres[m, 0]
            dy = points[i, 1] - centres[m, 1]
            dz = points[i, 2] - centres[m, 2]
            if dx * dx + dy * dy + dz * dz <= reach[m] * reach[m]:
                ok = False
                break
        keep[i] = ok


def _cell_keys(points: np.ndarray, edge: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Integer cell coordinates ``(N, 3)`` of cubes of ``edge``, one int64 key per cell, and the dims."""
    lo = points.min(axis=0)
    cell = np.floor((points - lo) / edge).astype(np.int64)
    dims = cell.max(axis=0) + 3  # room for the neighbours' offsets (cells shifted by one below)
    cell += 1
    key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    return cell, key, dims


def _voxel_centroids(points: np.ndarray, edge: float) -> np.ndarray:
    _, key, _ = _cell_keys(points, edge)
    uniq, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    out = np.empty((len(uniq), 3))
    for a in range(3):
        out[:, a] = np.bincount(inverse, weights=points[:, a], minlength=len(uniq)) / counts
    return out


def _inliers(points: np.ndarray, cleaning: Cleaning) -> np.ndarray:
    cell, key, dims = _cell_keys(points, cleaning.outlier_radius)
    order = np.argsort(key, kind="stable")
    sorted_keys = np.ascontiguousarray(key[order])
    pts = np.ascontiguousarray(points[order])
    stat = np.empty(len(points))
    k = cleaning.neighbours if cleaning.outliers == "statistical" else 0
    _neighbourhoods(
        pts, np.ascontiguousarray(cell[order]), sorted_keys, dims, cleaning.outlier_radius, k, stat
    )
    if cleaning.outliers == "radius":
        keep_sorted = stat >= cleaning.min_neighbours
    else:
        keep_sorted = stat <= stat.mean() + cleaning.std_ratio * stat.std()
    keep = np.empty(len(points), dtype=bool)
    keep[order] = keep_sorted
    return keep


@jit
def _neighbourhoods(points, cell, keys, dims, radius, k, out):
    """Per point (sorted by cell key): with ``k`` = 0 the number of other points within ``radius``; else
    the mean distance to its ``k`` nearest among the 27 cells around it (``radius`` for each not found)."""
    n = points.shape[0]
    best = np.empty(max(k, 1))
    r2 = radius * radius
    for i in range(n):
        count = 0
        for t in range(k):
            best[t] = radius
        for da in range(-1, 2):
            for db in range(-1, 2):
                for dc in range(-1, 2):
                    key = ((cell[i, 0] + da) * dims[1] + cell[i, 1] + db) * dims[2] + cell[i, 2] + dc
                    j = np.searchsorted(keys, key)
                    while j < n and keys[j] == key:
                        if j != i:
                            dx = points[j, 0] - points[i, 0]
                            dy = points[j, 1] - points[i, 1]
                            dz = points[j, 2] - points[i, 2]
                            d2 = dx * dx + dy * dy + dz * dz
                            if k == 0:
                                if d2 <= r2:
                                    count += 1
                            else:
                                d = math.sqrt(d2)
                                if d < best[k - 1]:  # insert into the sorted k best
                                    t = k - 1
                                    while t > 0 and best[t - 1] > d:
                                        best[t] = best[t - 1]
                                        t -= 1
                                    best[t] = d
                        j += 1
        if k == 0:
            out[i] = count
        else:
            s = 0.0
            for t in range(k):
                s += best[t]
            out[i] = s / k
