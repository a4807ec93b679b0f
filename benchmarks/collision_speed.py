"""Speed of the collision layer on one CPU thread: sphere centres, body–scene and self-collision
distances at large batches, a single-configuration check, and dense path checks; then the batch-1 path
check of a planner at batch 1 (the compiled kernel; one benchmark scene, 1 or 8 candidate paths) against
torch's check_path.

    python benchmarks/collision_speed.py [--batch 100000] [--threads 1] [--problems 20] [--batch1-only]

The large-batch scene has 5 spheres and 5 boxes (10 obstacles) and a floor; the body is the 12-sphere set
with (18 spheres) and without (12) the base's spheres; float32 unless stated. The batch-1 section uses
the held-out obstacle problems (benchmarks/data), float64.
"""

from __future__ import annotations

import argparse
import os
import statistics
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # NumPy's matrix products on one thread as well

import numpy as np
import torch
from _common import header, show, time_call, write_result

from kinlearn import load_robot
from kinlearn.collision import (
    Scene,
    body_obstacle_distance,
    body_spheres,
    check_path,
    in_collision,
    self_collision_distance,
)
from kinlearn.collision.kernel import KernelBody, KernelScene, check_paths, first_free
from kinlearn.data.problems import ProblemSet

HELDOUT = Path(__file__).resolve().parent / "data" / "obstacle_problems_heldout.npz"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--batch", type=int, default=100_000)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--problems", type=int, default=20, help="benchmark scenes of the batch-1 section")
    ap.add_argument("--batch1-only", action="store_true", help="only the batch-1 compiled path check")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(header("collision speed (iiwa14)", args.threads))
    robot = load_robot("iiwa14")
    figures: dict = {}
    if not args.batch1_only:
        large_batches(robot, args, figures)
    batch_one(robot, args.problems, figures)
    write_result(
        "collision_speed", figures, title="The collision layer's speed (iiwa14)", threads=args.threads
    )


def large_batches(robot, args, figures: dict) -> None:
    gen = torch.Generator().manual_seed(0)
    scene = Scene(
        torch.rand(5, 4, generator=gen) * 0.3 + torch.tensor([0.3, 0.0, 0.3, 0.05]),
        torch.rand(5, 6, generator=gen) * 0.2 + torch.tensor([0.4, 0.0, 0.2, 0.05, 0.05, 0.05]),
        floor=0.0,
    )
    rows = []
    q = robot.sample(args.batch, gen)
    for base in (False, True):
        body = body_spheres(robot, base=base).float()
        c = body(q)
        t_fk = time_call(lambda body=body: body(q, validate=False), repeats=3)
        t_obs = time_call(
            lambda body=body, c=c: body_obstacle_distance(c, body.radii, scene, floor_mask=body.floor_mask),
            repeats=3,
        )
        t_self = time_call(
            lambda body=body, c=c: self_collision_distance(c, body.radii, body.pairs), repeats=3
        )
        total = t_fk + t_obs + t_self
        rows.append(
            [
                f"{body.num_spheres} spheres, {len(body.pairs)} pairs",
                f"{args.batch:,}",
                f"{1e3 * t_fk:.0f}",
                f"{1e3 * t_obs:.0f}",
                f"{1e3 * t_self:.0f}",
                f"{1e3 * total:.0f}",
                f"{args.batch / total / 1e6:.2f}",
            ]
        )
    show(
        figures,
        "large batches",
        [
            "body",
            "configurations",
            "centres (ms)",
            "body–scene (ms)",
            "self (ms)",
            "all (ms)",
            "M configs/s",
        ],
        rows,
    )
    body = body_spheres(robot).float()
    q1 = q[:1]
    t1 = time_call(lambda: in_collision(body, q1, scene), repeats=200)
    body64 = body_spheres(robot).double()
    paths = torch.stack(
        [robot.sample(1000, gen, dtype=torch.float64), robot.sample(1000, gen, dtype=torch.float64)], 1
    )
    res = check_path(body64, paths, scene.to(torch.float64))
    t_paths = time_call(lambda: check_path(body64, paths, scene.to(torch.float64)), repeats=3)
    print(
        f"\nin_collision at batch 1 (18 spheres): {1e6 * t1:.0f} µs; check_path on 1,000 random straight "
        f"joint-space paths (float64, ≤ 1 cm sphere travel): {1e3 * t_paths:.0f} ms, "
        f"{int(res.checked.sum()):,} configurations checked ({int(res.checked.sum()) / t_paths / 1e6:.2f} M/s)"
    )


def _candidates(start: torch.Tensor, goal: torch.Tensor, n: int, seed: int) -> np.ndarray:
    """``(n, 11, 7)``: the straight joint line from start to goal, then n − 1 bent copies of it (inner knots
    moved by normal noise of 0.2 rad standard deviation per joint, tapering to 0 at both ends), as a
    learned planner's candidates might look."""
    f = torch.linspace(0, 1, 11, dtype=torch.float64)[:, None]
    line = start + f * (goal - start)
    gen = torch.Generator().manual_seed(seed)
    bump = torch.sin(torch.pi * f) * 0.2 * torch.randn(n - 1, 1, 7, generator=gen, dtype=torch.float64)
    return torch.cat([line[None], line + bump]).numpy()


def _time_problem(body, nbody, paths: np.ndarray, scene: Scene) -> tuple[float, ...]:
    """Median wall times (s) of the kernel's checks of 1 and 8 paths, first_free of 8, and torch's
    check_path of 1 and 8 paths, on one scene."""
    ns = KernelScene(scene)
    one, t_paths = paths[:1], torch.as_tensor(paths)
    return (
        time_call(lambda: check_paths(nbody, one, ns), repeats=100),
        time_call(lambda: check_paths(nbody, paths, ns), repeats=30),
        time_call(lambda: first_free(nbody, paths, ns), repeats=100),
        time_call(lambda: check_path(body, t_paths[:1], scene), repeats=5),
        time_call(lambda: check_path(body, t_paths, scene), repeats=3),
    )


def batch_one(robot, n_problems: int, figures: dict) -> None:
    """Batch 1 as a planner sees it: one scene, 1 or 8 candidate 11-knot paths; the kernel vs torch."""
    body = body_spheres(robot).double()
    nbody = KernelBody(body)
    problems = ProblemSet.load(HELDOUT)
    step = max(1, len(problems) // n_problems)
    names = (
        "check_paths, 1 path",
        "check_paths, 8 paths",
        "first_free, 8 paths",
        "torch, 1 path",
        "torch, 8 paths",
    )
    times = {name: [] for name in names}
    checked, scene_build = [], []
    for i in range(0, step * n_problems, step):
        start, goal, scene = problems.problem(i)
        paths = _candidates(start, goal, 8, seed=i)
        for name, t in zip(names, _time_problem(body, nbody, paths, scene), strict=True):
            times[name].append(t)
        scene_build.append(time_call(lambda scene=scene: KernelScene(scene), repeats=200))
        checked.append(int(check_path(body, torch.as_tensor(paths[:1]), scene).checked))
    med = statistics.median
    reference = {"check_paths, 1 path": "torch, 1 path", "check_paths, 8 paths": "torch, 8 paths"}
    reference["first_free, 8 paths"] = "torch, 8 paths"
    target = {"check_paths, 1 path": "≤ 100", "check_paths, 8 paths": "≤ 400", "first_free, 8 paths": ""}
    rows = []
    for name, ref in reference.items():
        t, r = times[name], times[ref]
        ratio = med(a / b for a, b in zip(r, t, strict=True))
        rows.append(
            [
                name,
                f"{1e6 * med(t):.0f}",
                f"{1e6 * max(t):.0f}",
                f"{1e6 * med(r):.0f}",
                f"{ratio:.0f}×",
                target[name],
            ]
        )
    caption = (
        f"Compiled path check at batch 1: {n_problems} held-out problems (every {step}th), float64, each a "
        f"straight 11-knot joint line and 7 bent copies; torch check_path on the same paths (median "
        f"{med(checked)} checked configurations per straight line). Median over problems of each one's "
        f"median wall time; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores."
    )
    print("\n" + caption)
    show(
        figures,
        "batch 1",
        [
            "call",
            "kernel median (µs)",
            "kernel worst (µs)",
            "torch check_path (µs)",
            "speed-up",
            "target (µs)",
        ],
        rows,
        caption=caption,
    )
    print(f"KernelScene from a Scene: {1e6 * med(scene_build):.1f} µs")


if __name__ == "__main__":
    main()
