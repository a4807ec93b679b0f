"""The batch-1 dense path check: the compiled kernel (kinlearn.collision.kernel) against the NumPy check
(benchmarks/_numpy_check.py) that the planner used before, timed in the same run on one thread.

    python benchmarks/dense_check_speed.py [--robot iiwa14] [--paths 200] [--repeats 20] [--threads 1]

Each path is a 12-knot joint path (iiwa14 by default; panda and ur5 have bodies too) (the straight joint
line between two configurations drawn within ±60% of the limits, seeded), checked against one scene of 10
primitives at a time with the robot's body (iiwa14: 18 spheres) and floor, ≤ 1 cm of sphere travel between
checked configurations:

- the verdict (``first_free`` of one path: collision-free or not), what a planner needs per candidate;
- the verdict and clearance (``check_paths``, every sub-step evaluated).

The NumPy check reads spheres and axis-aligned boxes only, so the ratio is measured on a scene of
5 spheres and 5 axis-aligned boxes; the kernel is also timed on a mixed scene (3 spheres, 4 rotated
boxes, 3 cylinders). Times are per path: the median over paths of the median of ``--repeats`` calls.
The first call's compile time (or load from numba's on-disk cache) is printed too.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import _numpy_check as numpy_check
import numpy as np
import torch
from _common import header, show, write_result

from kinlearn import load_robot
from kinlearn.collision import Scene, body_spheres
from kinlearn.collision.geometry import Box, Cylinder, Sphere, rotation_from_quaternion

CHECK_TRAVEL = 0.01


def scenes(seed: int = 0) -> tuple[Scene, Scene]:
    """(5 spheres + 5 axis-aligned boxes, 3 spheres + 4 rotated boxes + 3 cylinders), in the arm's reach."""
    rng = np.random.default_rng(seed)
    lo, hi = [0.25, -0.6, 0.15], [0.8, 0.6, 1.1]

    def centre():
        return rng.uniform(lo, hi)

    aligned = [Sphere(centre(), rng.uniform(0.04, 0.1)) for _ in range(5)]
    aligned += [Box(centre(), rng.uniform(0.03, 0.12, 3)) for _ in range(5)]
    R = [rotation_from_quaternion(q) for q in rng.normal(size=(7, 4))]
    mixed = [Sphere(centre(), rng.uniform(0.04, 0.1)) for _ in range(3)]
    mixed += [Box(centre(), rng.uniform(0.03, 0.12, 3), R[i]) for i in range(4)]
    mixed += [Cylinder(centre(), rng.uniform(0.03, 0.08), rng.uniform(0.05, 0.2), R[4 + i]) for i in range(3)]
    return Scene.from_primitives(aligned, floor=0.0), Scene.from_primitives(mixed, floor=0.0)


def paths(robot, n: int, seed: int = 0) -> np.ndarray:
    """``(n, 12, dof)`` straight joint lines between configurations within ±60% of the limits."""
    gen = torch.Generator().manual_seed(seed)
    mid = (robot.lower + robot.upper) / 2
    ends = mid + 0.6 * (robot.sample((n, 2), gen, dtype=torch.float64).numpy() - mid)
    f = np.linspace(0.0, 1.0, 12)[None, :, None]
    return np.ascontiguousarray(ends[:, :1] + f * (ends[:, 1:] - ends[:, :1]))


def per_path(fn, items, repeats: int) -> float:
    """Median over ``items`` of the median wall time of ``fn(item)`` over ``repeats`` calls (s)."""
    out = []
    for it in items:
        fn(it)
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter_ns()
            fn(it)
            times.append(time.perf_counter_ns() - t0)
        out.append(statistics.median(times) * 1e-9)
    return statistics.median(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--paths", type=int, default=200)
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--robot", default="iiwa14", help="iiwa14, panda or ur5")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    import numba

    print(header(f"batch-1 dense path check ({args.robot})", args.threads))
    print(f"numba {numba.__version__}")
    t0 = time.perf_counter()
    from kinlearn.collision import kernel

    kernel.warm_up()
    print(
        f"kernel import + first calls (compile, or load from numba's cache): {time.perf_counter() - t0:.2f} s"
    )

    robot = load_robot(args.robot)
    body = body_spheres(robot).double()
    kb, nb = kernel.KernelBody(body), numpy_check.NumpyBody(body)
    aligned, mixed = scenes()
    ka, km, na = (
        kernel.KernelScene(aligned),
        kernel.KernelScene(mixed),
        numpy_check.NumpyScene.from_scene(aligned),
    )
    P = paths(robot, args.paths)
    one = [P[i : i + 1] for i in range(len(P))]

    # The same verdicts first (and the kernel's exact clearance equal to NumPy's).
    kf, kc, kfirst = kernel.check_paths(kb, P, ka, CHECK_TRAVEL)
    nf, nc, nfirst = numpy_check.check_paths(nb, P, na, CHECK_TRAVEL)
    assert (kf == nf).all() and (kfirst == nfirst).all() and np.allclose(kc, nc, atol=1e-12)
    free_share = {
        name: float(kernel.check_paths(kb, P, s, CHECK_TRAVEL, exact=False)[0].mean())
        for name, s in (("aligned", ka), ("mixed", km))
    }

    t_nv = per_path(lambda p: numpy_check.first_free(nb, p, na, max_travel=CHECK_TRAVEL), one, args.repeats)
    t_kv = per_path(lambda p: kernel.first_free(kb, p, ka, max_travel=CHECK_TRAVEL), one, args.repeats)
    t_km = per_path(lambda p: kernel.first_free(kb, p, km, max_travel=CHECK_TRAVEL), one, args.repeats)
    t_ne = per_path(lambda p: numpy_check.check_paths(nb, p, na, CHECK_TRAVEL), one, args.repeats)
    t_ke = per_path(lambda p: kernel.check_paths(kb, p, ka, CHECK_TRAVEL), one, args.repeats)
    t_kme = per_path(lambda p: kernel.check_paths(kb, p, km, CHECK_TRAVEL), one, args.repeats)
    rows = [
        [
            "verdict (first_free)",
            "5 spheres + 5 boxes",
            f"{1e6 * t_nv:.1f}",
            f"{1e6 * t_kv:.1f}",
            f"{t_nv / t_kv:.1f}×",
        ],
        ["verdict (first_free)", "3 spheres + 4 rotated boxes + 3 cylinders", "—", f"{1e6 * t_km:.1f}", "—"],
        [
            "verdict + clearance (check_paths)",
            "5 spheres + 5 boxes",
            f"{1e6 * t_ne:.1f}",
            f"{1e6 * t_ke:.1f}",
            f"{t_ne / t_ke:.1f}×",
        ],
        ["verdict + clearance (check_paths)", "mixed", "—", f"{1e6 * t_kme:.1f}", "—"],
    ]
    caption = (
        f"{len(P)} paths of 12 knots, {body.num_spheres} spheres, {len(body.pairs)} self pairs, floor; "
        f"collision-free: {100 * free_share['aligned']:.0f}% (aligned scene), {100 * free_share['mixed']:.0f}% (mixed); "
        "median per path."
    )
    print(f"\n{caption}\n")
    figures: dict = {}
    show(
        figures,
        "dense check",
        ["check", "scene", "NumPy (µs)", "kernel (µs)", "NumPy / kernel"],
        rows,
        caption=caption,
    )
    write_result(
        "dense_check_speed",
        figures,
        title=f"The batch-1 dense path check: compiled kernel against NumPy ({robot.name})",
        threads=args.threads,
    )


if __name__ == "__main__":
    main()
