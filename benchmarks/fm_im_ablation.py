"""Which forward model and which inverse model make position goals work: the ablation on held-out
end-effector goals, each goal's joints judged by the analytic FK.

    python benchmarks/fm_im_ablation.py [--robot iiwa14] [--n 1000] [--threads 1]

FM kinds: the shipped MLP FM (``fm.pt``, the `improved` preset's difference form), the shipped chain
identified without a URDF (``chain.pt``), the analytic FK. IM kinds: the shipped MLP IM (``im.pt``)
stepped through the FM along the straight line (the planner's method without a chain), the analytic
one-step DLS IM stepped the same way, and the fixed-budget solver on the FM's own Jacobian
(:func:`kinlearn.models.chain.solve_position`; for the MLP FM its Jacobian by autograd, anchored at
the start's known end effector). Cells: the share of goals within 1 cm and the median error (mm).
"""

from __future__ import annotations

import argparse
import warnings

import torch
from _common import header

from kinlearn.body.kinematics import kinematics
from kinlearn.body.robot import load_robot
from kinlearn.errors import DomainWarning
from kinlearn.evaluation.workspace import heldout_pairs
from kinlearn.models.chain import solve_position
from kinlearn.models.forward_inverse import AnalyticFM, AnalyticIM, LearnedFM
from kinlearn.planning.planner import DEFAULT_CHECKPOINTS, Planner


class _AnchoredMLP:
    """An MLP FM in difference form as a function of the joints: p(θ) = ef(0) + g(θ) − g(θ(0))."""

    def __init__(self, fm: LearnedFM, theta0: torch.Tensor, ef0: torch.Tensor):
        self.fm, self.anchor = fm, ef0 - fm._g(theta0.float()).double()

    def position_and_jacobian(self, theta: torch.Tensor):
        n = theta.shape[0]
        flat = theta.reshape(-1, theta.shape[-1]).float()
        g = lambda t: self.fm._g(t)  # noqa: E731
        J = torch.vmap(torch.func.jacrev(g))(flat).double().reshape(*theta.shape[:-1], 3, theta.shape[-1])
        p = g(flat).double().reshape(*theta.shape[:-1], 3)
        anchor = self.anchor if theta.ndim == 2 else self.anchor.reshape(n, *([1] * (theta.ndim - 2)), 3)
        return p + anchor, J


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", default="iiwa14")
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    warnings.simplefilter("ignore", DomainWarning)
    print(header(f"FM × IM ablation on position goals ({args.robot})", args.threads))
    robot = load_robot(args.robot)
    shipped = Planner.load(DEFAULT_CHECKPOINTS / args.robot)
    fms = {
        "MLP FM (fm.pt)": shipped.fm,
        "chain (chain.pt, no URDF)": shipped.chain,
        "analytic": AnalyticFM(robot),
    }
    pairs = heldout_pairs(robot, args.n)
    q0, goal = pairs.start[:, : robot.dof].double(), pairs.goal[:, robot.dof :].double()
    fk = kinematics(robot)
    lo, hi = robot.limits(torch.float64)

    def judged(theta):
        e = (fk.position(theta.double()) - goal).norm(dim=-1) * 1e3
        return f"{float((e <= 10).double().mean()):.1%}, {float(e.median()):.2f}"

    print(f"\n{args.n:,} held-out goals within ±90% of the joint ranges; cells: ≤ 1 cm, median (mm)\n")
    print(
        "| FM | MLP IM stepped through the FM | analytic DLS IM stepped through the FM | solver on the FM's Jacobian |"
    )
    print("|:--|--:|--:|--:|")
    for label, fm in fms.items():
        cells = []
        for im in (shipped.im, AnalyticIM(robot)):
            stepping = Planner(robot, shipped.tm, fm, im)
            cells.append(
                judged(
                    torch.from_numpy(
                        stepping._reach_position(q0.numpy(), fk.position(q0).numpy(), goal.numpy())
                    )
                )
            )
        if isinstance(fm, LearnedFM):
            model = _AnchoredMLP(fm, q0, fk.position(q0))
            theta, _ = solve_position(model, q0, goal, lo, hi, backend="torch", restarts=1)
            cells.append(judged(theta) + " (from θ(0) alone: restarts need the FM's absolute position)")
        elif isinstance(fm, AnalyticFM):
            theta, _ = solve_position(fm.kin, q0, goal, lo, hi, backend="torch")
            cells.append(judged(theta))
        else:
            theta, _ = solve_position(fm, q0, goal, lo, hi)
            cells.append(judged(theta))
        print(f"| {label} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
