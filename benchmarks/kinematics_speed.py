"""Forward-kinematics throughput of each backend, as ratios to pytorch-kinematics measured in the same run.

    python benchmarks/kinematics_speed.py [--robot iiwa14] [--threads 2] [--max-batch 1000000]

Position FK at batch 1, 1e3, 1e5, 1e6 in float32 and float64, and the position Jacobian at batch 1e4.
Pinocchio runs one configuration at a time from Python (its natural use from Python); at large
batches it is timed on a subset and extrapolated per configuration, as is pytorch-kinematics above
1e5 (both scale linearly there).
"""

from __future__ import annotations

import argparse

import torch
from _common import header, show, time_call, write_result

from kinlearn import kinematics, load_robot

SUBSET = {"pinocchio": 20_000, "pk": 100_000}


def rate(kin, q: torch.Tensor, what: str) -> float:
    """Configurations per second."""
    n = q.shape[0]
    sub = min(n, SUBSET.get(kin.backend, n))
    fn = getattr(kin, what)
    qs = q[:sub]
    repeats = 5 if sub <= 1000 else (3 if sub <= 100_000 else 2)
    with torch.no_grad():
        t = time_call(lambda: fn(qs, validate=False), repeats=repeats)
    return sub / t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", default="iiwa14")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--max-batch", type=int, default=1_000_000)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    robot = load_robot(args.robot)
    print(header(f"kinematics speed: {robot.name} ({robot.dof} joints)", args.threads))
    backends = ("fast", "pk", "pinocchio")
    kins = {b: kinematics(robot, b) for b in backends}
    rows = []
    gen = torch.Generator().manual_seed(0)
    for dtype in (torch.float32, torch.float64):
        for batch in (1, 1_000, 100_000, 1_000_000):
            if batch > args.max_batch:
                continue
            q = robot.sample(batch, gen, dtype=dtype)
            r = {b: rate(kins[b], q, "position") for b in backends}
            rows.append(
                ["position", str(dtype).replace("torch.", ""), f"{batch:,}"]
                + [f"{r[b] / 1e6:.3f}" for b in backends]
                + [f"{r['fast'] / r['pk']:.1f}×", f"{r['fast'] / r['pinocchio']:.1f}×"]
            )
    for dtype in (torch.float32, torch.float64):
        q = robot.sample(10_000, gen, dtype=dtype)
        r = {b: rate(kins[b], q, "jacobian") for b in backends}
        rows.append(
            ["jacobian", str(dtype).replace("torch.", ""), "10,000"]
            + [f"{r[b] / 1e6:.3f}" for b in backends]
            + [f"{r['fast'] / r['pk']:.1f}×", f"{r['fast'] / r['pinocchio']:.1f}×"]
        )
    print()
    caption = "Throughput in million configurations per second (higher is better)."
    print(caption)
    figures: dict = {}
    show(
        figures,
        "throughput",
        [
            "what",
            "dtype",
            "batch",
            "fast",
            "pytorch-kinematics",
            "pinocchio loop",
            "fast / pk",
            "fast / pinocchio",
        ],
        rows,
        caption=caption,
    )
    write_result(
        "kinematics_speed",
        figures,
        title=f"Forward kinematics and Jacobians: three backends ({robot.name})",
        threads=args.threads,
    )


if __name__ == "__main__":
    main()
