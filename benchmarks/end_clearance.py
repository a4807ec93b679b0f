"""How close the held-out problems' ends lie to their obstacles: the margin a point cloud's check can afford.

    OMP_NUM_THREADS=1 python benchmarks/end_clearance.py [--robots panda ur5]

Per arm, on the committed held-out problems of the seven scene families
(``benchmarks/data/scene_problems_<arm>.npz``, the ur5's with its gripper), the clearance of the start and
of the goal: the smallest distance from a body sphere to the scene's true primitives (the compiled clearances,
:func:`kinlearn.collision.kernel.clearances`; the floor left out, as a cloud scene keeps it as a plane), the
smaller of the two ends per problem. Reported:
its quantiles, and the share of problems whose ends both clear a margin of 2, 5, 10 and 20 mm. A check of
sensed points is conservative by its margin (the points' radius plus its grid's bound), so a problem whose
end lies closer to a surface than that margin reads as starting or ending in collision among its points.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch
from _common import header, show, write_result

from kinlearn import load_robot
from kinlearn.collision import kernel as K
from kinlearn.data.problems import ProblemSet

DATA = Path(__file__).parent / "data"
MARGINS_MM = (2, 5, 10, 20)


def end_clearances(name: str) -> np.ndarray:
    """Each problem's smaller end clearance (mm)."""
    problems = ProblemSet.load(DATA / f"scene_problems_{name}.npz", robot=name)
    kb = K.KernelBody.of(problems.body(load_robot(name)).double())
    out = []
    for i in range(len(problems)):
        start, goal, scene = problems.problem(i)
        q = np.stack((start.double().numpy()[: kb.dof], goal.double().numpy()[: kb.dof]))
        scene_clear, _ = K.clearances(kb, K.KernelScene.of(scene.with_floor(None)), q)
        out.append(1e3 * float(np.min(scene_clear)))
    return np.asarray(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robots", nargs="+", default=["panda", "ur5"])
    args = ap.parse_args()
    torch.set_num_threads(1)
    print(header("End clearance of the held-out problems", 1))
    figures: dict = {}
    rows = []
    for name in args.robots:
        e = end_clearances(name)
        q = np.percentile(e, [10, 25, 50, 75, 90])
        shares = [float((e > m).mean()) for m in MARGINS_MM]
        figures[name] = {
            "problems": len(e),
            "quantiles_mm": dict(zip(("p10", "p25", "p50", "p75", "p90"), q.tolist(), strict=True)),
            "share_clear_of": {f"{m} mm": s for m, s in zip(MARGINS_MM, shares, strict=True)},
        }
        rows.append([name, len(e), *(f"{v:.1f}" for v in q), *(f"{100 * s:.0f}%" for s in shares)])
    show(
        figures,
        "end clearance",
        [
            "arm",
            "problems",
            "p10 mm",
            "p25 mm",
            "p50 mm",
            "p75 mm",
            "p90 mm",
            *(f"ends clear of {m} mm" for m in MARGINS_MM),
        ],
        rows,
        caption="The smaller of start's and goal's clearance to the true primitives (the floor left out), per problem.",
    )
    write_result(
        "end_clearance",
        figures,
        title="How close the held-out problems' ends lie to their obstacles",
        notes="The margin a conservative check of sensed points can afford on these problems.",
        threads=1,
    )


if __name__ == "__main__":
    main()
