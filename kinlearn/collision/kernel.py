"""The compiled collision checks (numba) for batch-1 planning, from Python: the dense path check
(:func:`check_paths`, :func:`first_free`, :func:`free_depths`), clearances of configurations
(:func:`clearances`), sphere centres (:func:`centres`) and the scene's distance at points
(:func:`point_distances`), on a body and a scene packed once (:class:`KernelBody`, :class:`KernelScene`).

torch (:mod:`kinlearn.collision.distance`, :func:`~kinlearn.collision.check_path`) stays the
implementation for training and large batches; these are its compiled twins for a single scene and a
handful of paths, where torch's per-operation dispatch dominates. The contract tests hold the two to each
other (``tests/test_collision_kernel.py``, and ``tests/test_collision_kinds.py`` kind by kind, with coal
as a third opinion). Importing this module loads numba (the planner imports it when it first checks a
path); every kernel compiles on its first call and ``cache=True`` keeps its machine code on disk
(:mod:`kinlearn.body.jit`); :func:`warm_up` compiles or loads them ahead.

Where the pieces live, one concept each: each kind of primitive (its rows, torch and compiled distance,
bounding radius) in :mod:`kinlearn.collision.kinds`; the body's FK in :mod:`kinlearn.body.fk`; the body's
packing and the pairs proven apart in :mod:`kinlearn.collision.kernel_body`; the scene's packing in
:mod:`kinlearn.collision.kernel_scene`; the dense check's walk in :mod:`kinlearn.collision.walk`; the
probe that answers "is this path free" sooner in :mod:`kinlearn.collision.probe`.

**The dense check** checks the configurations :func:`~kinlearn.collision.check_path` checks: segment k
is cut into n_k = ⌈L_k / max_travel⌉ sub-steps, L_k the largest lever bound Σ_j |Δθ_j| · lever_mj over
the spheres; every sub-step's start and the last knot are checked; one collides when its body–scene
distance is ≤ ``margin`` or a self-collision pair's distance is ≤ 0. Where only the verdict is wanted
(``first_free``, and ``check_paths(..., exact=False)``) sub-steps that provably cannot collide are
skipped: along a segment sphere m moves at most t_m = Σ_j |Δθ_j| lever_mj, so t_m / n_k per sub-step,
and its distance to the scene (1-Lipschitz in its centre) can fall by no more than that; a pair's
distance by no more than the sum of its spheres'. From a checked configuration whose per-sphere
clearances above ``margin`` (and pair distances above 0) are d_m, the next ⌊min_m (d_m − slack) /
(t_m / n_k)⌋ sub-steps are free and are not evaluated. The verdict and the first colliding segment are
those of checking every sub-step; only the clearance (a minimum over the evaluated configurations)
needs ``exact=True``. The refinements that keep that verdict and cut the work:

- **Many spheres at once.** Where many spheres are due at a configuration, the walk computes every
  sphere's distance in one loop over the spheres per primitive (vector instructions; the same values
  to the bit).
- **A self-collision pair closes at its own rate.** Turning joint j changes the distance ‖B − A‖ of a
  sphere B after it from a sphere A before it by at most |Δθ_j| times A's distance from the joint's
  axis (as well as B's lever), so a pair's budget is spent at Σ_j |Δθ_j| min(lever_Bj, axis_Aj) over
  the joints between them.
- **Pairs that cannot touch are left out.** :func:`proven_apart` proves, by branch and bound over the
  limits' box, which self-collision pairs never meet there, and the verdict drops them for paths whose
  knots all lie in that box (:attr:`KernelBody.packed_within`).
- **A probe first, where only the verdict is wanted**: a few grid configurations spread along the path
  (its inner knots, then each segment's middle sub-step, its quarters, eighths and sixteenths; among a
  problem's candidates first where the last ones hit) are checked against the scene, link by link
  behind a ball around each link's spheres. A probe hit is a grid configuration that collides, so the
  answer is the same.
- **The probe proves the scene clear as it goes.** Each configuration it finds clear also says how far
  along its segment the body stays clear; the grid configurations inside such a window are not looked
  at. The window is the longer of the global levers' and the bound at that configuration
  (:mod:`kinlearn.body.travel`: a point's own distances from the axes there, which only the later joints
  change), often by a third or more where the arm is folded. A path the probe passes is walked for the
  body against itself alone, then the gaps the windows left are filled until every configuration of the
  grid is proven clear of the scene or one is found that is not.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..body.jit import jit, ready

ready()  # numba loaded and every kernel decorated so far made a dispatcher, before the kernels below

from ..body.fk import KernelChain, _centres, checked_tips  # noqa: E402
from ..errors import ConfigError, NonFiniteError, ObstacleError  # noqa: E402
from .configurations import free_lanes  # noqa: E402
from .kernel_body import BOX_SLACK, KernelBody, _all_finite, _joints, near_pairs, proven_apart  # noqa: E402
from .kernel_scene import KernelScene, point_distances  # noqa: E402

# The compiled entry points other compiled code calls (the sampler, OMPL's checker, the shortcut pass),
# under the names they had here.
from .kinds import sphere_scene as _sphere_scene  # noqa: E402, F401
from .kinds import spheres_scene as _spheres_scene  # noqa: E402, F401
from .probe import _first_free_packed as _first_free_packed  # noqa: E402
from .probe import _free_packed as _free_packed  # noqa: E402
from .probe import first_free_boxed, free_depths_boxed  # noqa: E402
from .scene import Scene  # noqa: E402
from .walk import _check, _verdict_packed  # noqa: E402
from .walk import _clearances as _clearances  # noqa: E402
from .walk import _grid_steps as _grid_steps  # noqa: E402

__all__ = [
    "BOX_SLACK",
    "KernelBody",
    "KernelChain",
    "KernelScene",
    "centres",
    "check_paths",
    "checked_tips",
    "clearances",
    "first_free",
    "first_free_boxed",
    "free_configurations",
    "free_depths",
    "free_depths_boxed",
    "near_pairs",
    "point_distances",
    "proven_apart",
    "warm_up",
]


def _check_args(body, scene, max_travel, margin) -> None:
    if (
        type(body) is KernelBody
        and type(scene) is KernelScene
        and type(max_travel) is float
        and type(margin) is float
        and 0.0 < max_travel < math.inf
        and -math.inf < margin < math.inf
    ):
        return  # the common case, in a few comparisons
    if not isinstance(body, KernelBody):
        raise ConfigError(
            f"body must be a KernelBody (KernelBody(body_spheres(robot))), got {type(body).__name__}"
        )
    if not isinstance(scene, KernelScene):
        raise ObstacleError(f"scene must be a KernelScene (KernelScene(scene)), got {type(scene).__name__}")
    if not (isinstance(max_travel, (int, float)) and math.isfinite(max_travel) and max_travel > 0):
        raise ConfigError(f"max_travel must be a finite number of metres > 0, got {max_travel!r}")
    if not (isinstance(margin, (int, float)) and math.isfinite(margin)):
        raise ConfigError(f"margin must be a finite number of metres, got {margin!r}")


def centres(body: KernelBody, q) -> np.ndarray:
    """World sphere centres ``(N, M, 3)`` of joints ``q (N, dof)``."""
    return _centres(_joints(q, body.dof, "joint values q", 2), *body.fk_args())


def clearances(body: KernelBody, scene: KernelScene, q, per_sphere: bool = False):
    """``(scene clearance (N,), self clearance (N,))`` of configurations ``q (N, dof)`` (and, with
    ``per_sphere``, each sphere's distance to the scene ``(N, M)``): the numbers of
    :func:`kinlearn.collision.clearances`."""
    _check_args(body, scene, 1.0, 0.0)
    qs = _joints(q, body.dof, "joint values q", 2)
    per = np.empty((qs.shape[0], body.num_spheres))
    d, s = _clearances(qs, *body.args(), *scene.args(), per)
    return (d, s, per) if per_sphere else (d, s)


def free_configurations(body: KernelBody, scene: KernelScene, q, margin: float = 0.0) -> np.ndarray:
    """``(N,)`` bool: whether each configuration of ``q (N, dof)`` is free under the dense check — no
    sphere within ``margin`` of the scene or the floor, no self-collision pair touching — in one compiled
    call over all of them (:func:`~kinlearn.collision.configurations.free_lanes`: the configurations in
    lanes, each link's ball before its spheres, a configuration dropped at its first contact). The
    verdicts of :func:`check_paths` on one-configuration paths, and of :func:`clearances`' rule
    (scene clearance > ``margin`` and self clearance > 0). Raises :class:`~kinlearn.errors.NonFiniteError`
    for NaN or infinity."""
    _check_args(body, scene, 1.0, margin)
    qs = _joints(q, body.dof, "joint values q", 2)
    free = np.empty(qs.shape[0], dtype=np.bool_)
    free_lanes(qs, float(margin), *body.packing_of(qs), scene.packed, free)
    return free


def check_paths(
    body: KernelBody,
    paths,
    scene: KernelScene,
    max_travel: float = 0.01,
    margin: float = 0.0,
    exact: bool = True,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Check joint paths ``paths (P, T+1, dof)`` against one scene and self-collision, densely.

    Returns ``(free (P,) bool, clearance (P,), first_collision (P,) int64)``: per path the
    ``collision_free``, ``clearance`` and ``first_collision`` of :func:`~kinlearn.collision.check_path`
    (the same sub-steps, pairs and floor rule; touching counts as a collision). ``exact=False`` skips the
    sub-steps that cannot collide and stops at a path's first collision: the same ``free`` and
    ``first_collision``, and no clearance (NaN).
    """
    _check_args(body, scene, max_travel, margin)
    arr = _joints(paths, body.dof, "joint paths", 3)
    P = arr.shape[0]
    free, clear, first = np.zeros(P, dtype=bool), np.empty(P), np.empty(P, dtype=np.int64)
    for i in range(P):
        if exact:
            first[i], clear[i], _, _ = _check(
                arr[i], float(max_travel), float(margin), True, *body.args(), body.lever, *scene.args()
            )
        else:
            first[i], _, _, _ = _verdict_packed(
                arr[i], float(max_travel), float(margin), *body.packing_of(arr[i]), scene.packed
            )
            clear[i] = np.nan
        free[i] = first[i] < 0
    return free, clear, first


def free_depths(
    body: KernelBody,
    theta,
    vias,
    scene: KernelScene,
    max_travel: float = 0.01,
    margin: float = 0.0,
) -> np.ndarray:
    """``(D,)``: per chain of ``vias (D, L, dof)`` from ``theta (dof,)``, how many of its vias the polyline
    ``[theta, vias[d]]`` reaches through segments :func:`check_paths` finds free (0: its first segment
    collides; L: all free), in one compiled call. Each chain is walked once to its first collision: a
    hit found in segment f (f > 0) lies in it or at its first knot, via f − 1, which the segment before
    ends at; checked alone, that via tells which (the depths of checking every segment apart, to the
    bit). Raises :class:`~kinlearn.errors.NonFiniteError` for NaN or infinity."""
    _check_args(body, scene, max_travel, margin)
    theta = _joints(theta, body.dof, "theta", 1, finite=False)
    vias = _joints(vias, body.dof, "vias", 3, finite=False)
    depth = np.empty(vias.shape[0], dtype=np.int64)
    if not free_depths_boxed(theta, vias, float(max_travel), float(margin), *body.boxed, scene.packed, depth):
        raise NonFiniteError("theta or the vias hold NaN or infinity")
    return depth


def first_free(
    body: KernelBody,
    paths,
    scene: KernelScene,
    order: Sequence[int] | np.ndarray | None = None,
    max_travel: float = 0.01,
    margin: float = 0.0,
) -> int:
    """The index of the first path in ``order`` (default 0, 1, …) that :func:`check_paths` finds
    collision-free, or −1 if none is. ``order`` must hold distinct indices into ``paths`` (a
    :class:`~kinlearn.errors.ConfigError` otherwise); it may leave paths out."""
    _check_args(body, scene, max_travel, margin)
    arr = _joints(paths, body.dof, "joint paths", 3, finite=False)  # the kernel checks finiteness
    P = arr.shape[0]
    if order is None:
        idx = _NATURAL[P] if P < len(_NATURAL) else np.arange(P, dtype=np.int64)
    else:
        idx = np.asarray(order)
        if idx.ndim != 1 or (idx.size and idx.dtype.kind not in "iu"):
            raise ConfigError(f"order must be a 1-D sequence of path indices, got {order!r}")
        idx = np.ascontiguousarray(idx, dtype=np.int64)
        if idx.size and not _distinct_indices(idx, P):
            raise ConfigError(f"order must hold distinct path indices in 0…{P - 1}, got {idx.tolist()}")
    if idx.shape[0] == 0:
        if not _all_finite(arr):
            raise NonFiniteError(f"joint paths hold {int((~np.isfinite(arr)).sum())} NaN/inf value(s)")
        return -1
    k = int(first_free_boxed(arr, idx, float(max_travel), float(margin), *body.boxed, scene.packed))
    if k == -2:
        raise NonFiniteError(f"joint paths hold {int((~np.isfinite(arr)).sum())} NaN/inf value(s)")
    return k


#: The order 0, 1, …, P − 1 of a few paths, made once (never written: the kernels only read it).
_NATURAL = [np.arange(P, dtype=np.int64) for P in range(33)]


def warm_up() -> None:
    """Compile (or load from numba's cache) every kernel now, on a tiny problem."""
    from ..body.robot import load_robot
    from .body import body_spheres

    robot = load_robot("iiwa14")
    body = KernelBody(body_spheres(robot).double())
    scene = KernelScene(Scene.from_spheres([[0.5, 0.0, 0.5, 0.1]], floor=0.0))
    path = np.zeros((1, 2, body.dof))
    check_paths(body, path, scene)
    check_paths(body, path, scene, exact=False)
    first_free(body, path, scene)
    first_free(body, path, scene, order=[0])
    free_depths(body, path[0, 0], path, scene)
    clearances(body, scene, path[0])
    free_configurations(body, scene, path[0])
    centres(body, path[0])
    point_distances(scene, np.zeros((1, 3)))
    scene.model_rows()
    chain = KernelChain.of(robot)
    chain.position(path[0])
    chain.checked(path[0], 1e-6)


@jit
def _distinct_indices(idx, n):
    """Every entry of ``idx`` in 0…n−1, none twice."""
    seen = np.zeros(n, dtype=np.bool_)
    for i in idx:
        if i < 0 or i >= n or seen[i]:
            return False
        seen[i] = True
    return True
