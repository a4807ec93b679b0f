"""How far a point fixed in a link can travel along a joint-space segment, bounded at a configuration of
it (compiled): how far the collision probe's clear configurations prove the grid around them clear
(:mod:`kinlearn.collision.probe`).

Along a segment θ(s) = θ_a + s Δ (s ∈ [0, 1]), a point x fixed in link l moves at speed at most
Σ_{j<l} |Δ_j| ρ_j, ρ_j its distance from joint j's axis (1 for a prismatic joint, which moves every point
by its own displacement). The global bound takes each ρ_j at its largest over all configurations (the
body's ``lever``, :func:`~kinlearn.collision.body_bounds._lever_arms`); at a configuration of the segment
the point's own distances ρ_j are known, and only the joints after j change ρ_j, at a rate of at most
G_j = Σ_{j<i<l} |Δ_i| lever_i. Over a share u of the segment, either way from that configuration, the
point therefore travels at most

    D(u) = min(A u + B u² / 2, C u),   A = Σ_{j<l} |Δ_j| ρ_j,  B = Σ_{j<l} |Δ_j| G_j,  C = Σ_j |Δ_j| lever_j,

and a clearance b lasts for the share :func:`window` solves D(u) = b for. Where the arm is folded or
the point lies near the axes that turn most, A is a fraction of C (about 0.5–0.6 of it at the median of
uniform panda and ur5 configurations, 0.86 for the iiwa14) and the windows are longer by as much. The
probe bounds a link's ball by its centre's travel (the ball's centre lies among its spheres', so their
levers bound its own) and a sphere looked at alone by its own centre's.
"""

from __future__ import annotations

import math

from .jit import jit

__all__: list[str] = []


@jit(inline="always")
def axis_speed(frames, x, y, z, lk, path, k, prismatic):
    """A = Σ_{j<lk} |Δ_j| ρ_j of the point ``(x, y, z)`` fixed in link ``lk`` (moved by joints 0…lk − 1) at
    the configuration whose frames are ``frames`` (:func:`~kinlearn.body.fk._chain`'s; joint j's axis is
    the z axis of ``frames[j + 1]``), along segment ``k`` of ``path``: its speed bound there per unit of
    the segment's share."""
    a = 0.0
    for j in range(min(lk, path.shape[1])):
        dj = abs(path[k + 1, j] - path[k, j])
        if dj == 0.0:
            continue
        if prismatic[j]:
            a += dj
            continue
        ax, ay, az = frames[j + 1, 0, 2], frames[j + 1, 1, 2], frames[j + 1, 2, 2]
        vx, vy, vz = x - frames[j + 1, 0, 3], y - frames[j + 1, 1, 3], z - frames[j + 1, 2, 3]
        cx, cy, cz = vy * az - vz * ay, vz * ax - vx * az, vx * ay - vy * ax
        a += dj * math.sqrt(cx * cx + cy * cy + cz * cz)
    return a


@jit(inline="always")
def growth(path, k, lk, lever, row):
    """B = Σ_{j<lk} |Δ_j| Σ_{j<i<lk} |Δ_i| lever[row, i] for a point of link ``lk`` whose levers are
    ``lever[row]`` (upper bounds on its distances from the axes), along segment ``k`` of ``path``."""
    b = 0.0
    after = 0.0  # Σ_{i>j} |Δ_i| lever_i, from the last joint down
    for j in range(min(lk, path.shape[1]) - 1, -1, -1):
        dj = abs(path[k + 1, j] - path[k, j])
        b += dj * after
        after += dj * lever[row, j]
    return b


@jit(inline="always")
def window(b, a, g, c):
    """The largest share u of a segment over which a point travels at most ``b`` metres (see the module
    docstring; ``a``, ``g``, ``c``: its A, B and C): the larger of the global bound's b / C and the local
    bound's root of A u + B u² / 2 = b (written 2b / (A + √(A² + 2 B b)), exact where B is 0); +inf where
    nothing moves the point, 0 for no budget."""
    if not b > 0.0:
        return 0.0
    u = b / c if c > 0.0 else math.inf
    if a > 0.0 or g > 0.0:
        u = max(u, 2.0 * b / (a + math.sqrt(a * a + 2.0 * g * b)))
    else:
        u = math.inf
    return u
