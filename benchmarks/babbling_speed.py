"""Motor-babbling throughput (transitions per second) against naive ways of computing the same data.

    python benchmarks/babbling_speed.py [--robot iiwa14] [--threads 2] [--transitions 1000000]

Rows (float32, measured in one run, ratios against the slowest baseline):

- ``kinlearn.babble``: the walk vectorised over walkers, then FK once per state on the whole batch
  with the fast kinematics path (s(t+1) of a transition is s(t) of the next).
- ``per-step fast FK of s and s'``: the same walk, but FK evaluated inside the step loop on every
  transition's s and s' (twice per state), batch = walkers.
- ``pytorch-kinematics FK once per state``: the same walk, ef by pytorch-kinematics on all states.
- ``per-step pytorch-kinematics FK of s and s'``: the straightforward implementation.

pytorch-kinematics rows are timed on a tenth of the transitions and scaled linearly (their cost is
linear in the number of FK evaluations at these batch sizes).
"""

from __future__ import annotations

import argparse

import torch
from _common import header, show, time_call, write_result

from kinlearn import kinematics, load_robot
from kinlearn.body.state import StateLayout
from kinlearn.data.babbling import BabblingConfig, _walk, babble


def per_step(robot, cfg: BabblingConfig, backend: str) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Transitions with FK inside the step loop, on s and on s' of every transition."""
    kin = kinematics(robot, backend)
    L = StateLayout(robot.dof)
    theta = _walk(robot, cfg, torch.Generator().manual_seed(cfg.seed), torch.float32)
    s, a, s_next = [], [], []
    for t in range(cfg.steps):
        q0, q1 = theta[t], theta[t + 1]
        s.append(L.join(q0, kin.position(q0, validate=False)))
        s_next.append(L.join(q1, kin.position(q1, validate=False)))
        a.append(q1 - q0)
    return torch.cat(s), torch.cat(a), torch.cat(s_next)


def once_per_state(robot, cfg: BabblingConfig, backend: str):
    kin = kinematics(robot, backend)
    L = StateLayout(robot.dof)
    theta = _walk(robot, cfg, torch.Generator().manual_seed(cfg.seed), torch.float32)
    states = L.join(theta, kin.position(theta, validate=False))
    return (
        states[:-1].reshape(-1, L.size),
        (theta[1:] - theta[:-1]).reshape(-1, robot.dof),
        states[1:].reshape(-1, L.size),
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", default="iiwa14")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--transitions", type=int, default=1_000_000)
    ap.add_argument("--walkers", type=int, default=1000)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    robot = load_robot(args.robot)
    print(header(f"babbling speed: {robot.name} ({robot.dof} joints), float32", args.threads))

    cfg = BabblingConfig.for_transitions(args.transitions, walkers=args.walkers, robot=robot.name)
    sub = BabblingConfig.for_transitions(args.transitions // 10, walkers=args.walkers, robot=robot.name)
    # The baselines compute the same data as babble() (checked on the small config).
    ref = babble(sub, robot)
    for fn, backend in ((per_step, "fast"), (once_per_state, "pk"), (per_step, "pk")):
        for x, y in zip(ref.tensors(), fn(robot, sub, backend), strict=True):
            assert torch.allclose(x, y, atol=1e-5), f"{fn.__name__}/{backend} computes other data"

    with torch.no_grad():
        rows_in = [
            ("kinlearn.babble (vectorised walk, FK once per state)", cfg, lambda c: babble(c, robot)),
            ("per-step fast FK of s and s'", cfg, lambda c: per_step(robot, c, "fast")),
            ("pytorch-kinematics FK once per state", sub, lambda c: once_per_state(robot, c, "pk")),
            ("per-step pytorch-kinematics FK of s and s'", sub, lambda c: per_step(robot, c, "pk")),
        ]
        rates = []
        for name, c, fn in rows_in:
            t = time_call(lambda fn=fn, c=c: fn(c), repeats=3)
            rates.append((name, c.transitions, c.transitions / t))
    slowest = min(r for _, _, r in rates)
    ours = rates[0][2]
    rows = [
        [
            name,
            f"{n:,}" + ("" if n == cfg.transitions else " (scaled)"),
            f"{rate / 1e6:.2f}",
            f"{cfg.transitions / rate:.2f}",
            f"{rate / slowest:.0f}×",
            f"{ours / rate:.1f}×",
        ]
        for name, n, rate in rates
    ]
    print()
    figures: dict = {}
    show(
        figures,
        "throughput",
        [
            "method",
            "transitions timed",
            "M transitions/s",
            f"s per {cfg.transitions / 1e6:g} M",
            "vs slowest",
            "babble() is faster by",
        ],
        rows,
        caption=f"{cfg.walkers} walkers × {cfg.steps} steps, float32.",
    )
    print(f"\n{cfg.walkers} walkers × {cfg.steps} steps: {cfg.transitions / ours:.2f} s")
    write_result(
        "babbling_speed",
        figures,
        title=f"Motor babbling throughput ({robot.name})",
        threads=args.threads,
    )


if __name__ == "__main__":
    main()
