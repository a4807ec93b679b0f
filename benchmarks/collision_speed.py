"""Speed of the collision layer on one CPU thread: sphere centres, body–scene and self-collision
distances at large batches, a single-configuration check, and dense path checks.

    python benchmarks/collision_speed.py [--batch 100000] [--threads 1]

The scene has 5 spheres and 5 boxes (10 obstacles) and a floor; the body is the 12-sphere set with
(18 spheres) and without (12) the base's spheres; float32 unless stated.
"""

from __future__ import annotations

import argparse

import torch
from _common import header, markdown_table, time_call

from kinlearn import load_robot
from kinlearn.collision import (
    Scene,
    body_obstacle_distance,
    body_spheres,
    check_path,
    in_collision,
    self_collision_distance,
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--batch", type=int, default=100_000)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(header("collision speed (iiwa14)", args.threads))
    robot = load_robot("iiwa14")
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
    print(
        markdown_table(
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


if __name__ == "__main__":
    main()
