"""Which forward model and which inverse model make position goals (and the paper's task) work: the
FM × IM ablation with the shipped models, every result judged by the analytic FK.

    python benchmarks/fm_im_ablation.py [--robot iiwa14] [--n 1000] [--threads 1]

FM kinds: the shipped MLP FM (``fm.pt``, the `improved` preset's difference form), the shipped chain
identified without a URDF (``chain.pt``), the analytic FK. IM kinds: the shipped MLP IM (``im.pt``)
and the analytic one-step DLS IM, each stepped through the FM along the straight line, and damped
least squares on the FM's own Jacobian (see :mod:`kinlearn.evaluation.fm_im`). Position goals only:
the paper task's ablation needs a waypoint TM, which ``kinlearn reproduce`` trains.
"""

from __future__ import annotations

import argparse
import warnings

import torch
from _common import from_markdown, header, write_result

from kinlearn.body.robot import load_robot
from kinlearn.errors import DomainWarning
from kinlearn.evaluation.fm_im import fm_im_ablation, fm_im_table
from kinlearn.evaluation.workspace import heldout_pairs
from kinlearn.models.forward_inverse import AnalyticFM
from kinlearn.planning.planner import DEFAULT_CHECKPOINTS, Planner


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
    results = fm_im_ablation(robot, fms, shipped.im, heldout_pairs(robot, args.n))
    caption = f"{args.n:,} held-out goals within ±90% of the joint ranges; cells: ≤ 1 cm (median)."
    print(f"\n{caption}\n")
    print(fm_im_table(results))
    write_result(
        "fm_im_ablation",
        {"position goals": from_markdown(fm_im_table(results), caption=caption)},
        title=f"Which FM, which IM: position goals ({robot.name})",
        threads=args.threads,
    )


if __name__ == "__main__":
    main()
