"""A plan's start or goal in contact with a sensed cloud: the surface the points sample, within the sensor's
noise of the arm's body.

A point is an obstacle ball of the cloud's radius, which covers the gaps between a surface's samples and
the sensor's noise; so an arm that touches a surface, or comes within a centimetre of it, reads as
colliding with its points there, though it does not collide with the surface. At a plan's ends that
refusal is most of what goes wrong among clouds: a goal at a shelf, on a table, in a bin lies millimetres
from the surface it works on. :func:`ends_in_contact` tells the two apart by depth: an end whose body
the balls touch but whose spheres hold no point deeper than the cloud's ``contact`` (m, its
:attr:`~kinlearn.collision.cloud.PointCloud.contact`) is taken to touch the surface those points sample,
and the points within :data:`CONTACT_MARGIN` of its body there are dropped for the plan, as for a goal
vouched for (:class:`~kinlearn.collision.cloud.Cleaning`'s ``vouch_margin``); an end with a point deeper
inside is left colliding, and refused. A cloud of ``contact=0`` refuses every end its balls touch.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .cloud_cleaning import Cleaning
from .kernel import centres
from .kernel_body import KernelBody
from .scene import Scene

__all__ = ["CONTACT_MARGIN", "Contact", "ends_in_contact"]

#: Metres about the body at an end in contact within which points are taken as the surface it touches
#: (:class:`Cleaning`'s ``vouch_margin``: room for the sensor's noise).
CONTACT_MARGIN = Cleaning().vouch_margin


class Contact(NamedTuple):
    """One end in contact with the cloud."""

    #: ``"start"`` or ``"goal"``.
    end: str
    #: Metres its deepest point lies inside its body (negative: the points' balls touch it, no point does).
    depth: float


def ends_in_contact(body: KernelBody, scene: Scene, q: np.ndarray) -> tuple[Scene, list[Contact]]:
    """``scene`` (unbatched, with a cloud) for the plan from ``q[0]`` to ``q[1]`` (float64 ``(2, dof)``,
    finite): where an end's body touches the cloud's balls with no point deeper inside it than the cloud's
    :attr:`~kinlearn.collision.cloud.PointCloud.contact`, the scene without the points within
    :data:`CONTACT_MARGIN` of the body there; and those ends (:class:`Contact`). The same scene and no end
    where none is in contact (also where an end is deeper: it collides, and the plan says so)."""
    cloud = scene.cloud
    if cloud is None or cloud.contact <= 0.0:
        return scene, []
    radii = body.radii
    c = centres(body, q)  # (2, M, 3)
    M = radii.shape[0]
    # each sphere's centre to the nearest point's ball (exact where it comes within the cloud's EXACT)
    d = cloud.distance(c.reshape(-1, 3), np.tile(radii, 2)).reshape(2, M)
    touching = (d - radii <= 0.0).any(axis=1)
    if not touching.any():
        return scene, []
    depth = (radii - (d + cloud.radius)).max(axis=1)  # the deepest point's depth inside the body
    found = [
        Contact(("start", "goal")[e], float(depth[e]))
        for e in (0, 1)
        if touching[e] and depth[e] <= cloud.contact
    ]
    if not found:
        return scene, []
    at = np.concatenate([c[0 if k.end == "start" else 1] for k in found])
    reach = np.tile(radii, len(found)) + CONTACT_MARGIN + cloud.radius
    return scene.with_cloud(cloud.without_near(at, reach)), found
