"""Leave one family out, every family: train the obstacle network without it, plan its held-out problems.

    python benchmarks/leave_one_out.py --robot iiwa14 [--families bookcase cubby …] [--iterations 3000]
        [--candidates C] [--problems-per-family 200] [--solvable-only] [--base all] [--run-root runs/loo/iiwa14] [--problems-dir DIR]
        [--problems benchmarks/data/scene_problems_iiwa14.npz] [--out runs/benchmarks/loo_iiwa14]

For each family F of ``--families`` (default: the seven scene families) a network is trained with
``kinlearn train-obstacle-planner --families BASE --leave-out F`` (the same problems, seeds, iterations,
candidates and feasibility filter as the network trained on every family; a run already in ``RUN_ROOT/without-F`` is
used if its log says it finished, resumed if not), put into a copy of the shipped planner's folder, and asked for
fixed-time plans (``refine_steps=0``: the learned proposals, then the retreat stage), the same without the
retreat stage (``retreat=False``: the network alone) and plans with ``deadline=0.05`` on the held-out
problems of ``--problems`` (seeds apart from every training seed; verified solvable).
Every plan is judged by :func:`kinlearn.evaluation.obstacles.obstacle_outcome` with the body the held-out
problems were made for, and the networks are trained for that body (``--sphere-set``; the ur5's committed
set: its arm with the gripper; ``--problems benchmarks/data/scene_problems_ur5_arm.npz``: the arm alone),
and within the limits they were made within (``--problems benchmarks/data/scene_problems_ur5_within.npz``:
the networks train with ``--within body`` and plans are judged within the benchmarks' UR5 limits, ±π).

The table gives per left-out family its fixed-time success (the network never saw it), the network alone's
on it, the same network's fixed-time success on the families it saw, the straight line's on the left-out
family, the reference network's (``--reference``: a planner folder whose network saw every family;
default the shipped one) on it, with and without the retreat stage, and the deadline's. Batch 1, one thread. Training takes minutes per family on the iiwa14 and
longer on the arms with many body spheres (see ``kinlearn/checkpoints/README.md``).
"""

from __future__ import annotations

import argparse
import inspect
import json
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import torch
from _common import RUNS, from_markdown, header, markdown_table, write_result

import kinlearn
from kinlearn.data.problems import FAMILIES, ProblemSet, select_families
from kinlearn.errors import NoObstacleModelWarning
from kinlearn.evaluation.obstacles import obstacle_outcome
from kinlearn.planning.obstacle_baselines import joint_line_path

DATA = Path(__file__).parent / "data"
SCENE_FAMILIES = select_families("scenes")


def train(robot: str, family: str, args, run: Path) -> Path:
    """The network trained without ``family`` (trained now unless ``run`` already holds it)."""
    out = run / "tm_obstacles.pt"
    log = run / "metrics.jsonl"
    if out.exists() and log.exists():
        lines = log.read_text().splitlines()
        if lines and json.loads(lines[-1]).get("iteration", 0) >= args.iterations:
            print(f"  without {family}: {out} (finished: {args.iterations} iterations)", flush=True)
            return out
    cmd = [
        sys.executable, "-m", "kinlearn", "train-obstacle-planner", "--robot", robot,
        "--families", *args.base, "--leave-out", family,
        "--problems-per-family", str(args.problems_per_family), "--iterations", str(args.iterations),
        "--candidates", str(args.candidates), "--problems-dir", str(args.problems_dir),
        "--run-dir", str(run), "--no-progress", "--sphere-set", args.sphere_set, "--within", args.within,
    ]  # fmt: skip
    if args.solvable_only:
        cmd.append("--solvable-only")
    if (run / "config.json").exists():  # an interrupted run goes on
        cmd.append("--resume")
    print("  " + " ".join(cmd[2:]), flush=True)
    subprocess.run(cmd, check=True)
    return out


def planner_with(network: Path, robot: str, folder: Path, body) -> kinlearn.Planner:
    """The shipped planner of ``robot`` with ``network`` as its obstacle network (a folder copy), checking
    with ``body`` (the body the problems were made for)."""
    folder.mkdir(parents=True, exist_ok=True)
    shipped = Path(kinlearn.__file__).parent / "checkpoints" / robot
    for f in shipped.glob("*.pt"):
        shutil.copy2(f, folder / f.name)
    shutil.copy2(network, folder / "tm_obstacles.pt")
    return kinlearn.Planner.load(folder, body=body)


def success(planner, problems, body, **kw) -> np.ndarray:
    paths = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NoObstacleModelWarning)
        for i in range(len(problems)):
            start, goal, scene = problems.problem(i)
            paths.append(torch.as_tensor(planner.plan(start, goal, obstacles=scene, **kw).joints))
    return obstacle_outcome(body, paths, problems)["success"].numpy()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", default="iiwa14")
    ap.add_argument(
        "--families", nargs="*", default=list(SCENE_FAMILIES), help="families to leave out in turn"
    )
    ap.add_argument(
        "--base", nargs="*", default=["all"], help="what every network trains on, less the one left out"
    )
    ap.add_argument("--iterations", type=int, default=3000)
    ap.add_argument(
        "--candidates", type=int, default=None, help="paths per problem (default: the reference network's)"
    )
    ap.add_argument("--problems-per-family", type=int, default=200)
    ap.add_argument(
        "--solvable-only",
        action="store_true",
        help="train on the problems the sampler solves only (as the panda's and the ur5's shipped networks)",
    )
    ap.add_argument("--run-root", type=Path, default=None)
    ap.add_argument(
        "--problems-dir", type=Path, default=None, help="training problems (default RUN_ROOT/problems)"
    )
    ap.add_argument("--problems", type=Path, default=None)
    ap.add_argument(
        "--reference", type=Path, default=None, help="planner folder of a network that saw every family"
    )
    ap.add_argument("--deadline", type=float, default=0.05)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    torch.set_num_threads(1)
    args.run_root = args.run_root or Path("runs") / "loo" / args.robot
    args.problems_dir = args.problems_dir or args.run_root / "problems"
    out = args.out or RUNS / f"loo_{args.robot}"
    out.mkdir(parents=True, exist_ok=True)
    print(header(f"Leave one family out ({args.robot})", 1))
    problems = ProblemSet.load(args.problems or DATA / f"scene_problems_{args.robot}.npz", robot=args.robot)
    robot = kinlearn.load_robot(args.robot)
    body = problems.body(robot).double()  # the body the problems were made for
    args.sphere_set = body.name  # and the networks are trained for it
    # a set made within the body's limits (the ur5's tool model: ±π) is trained for (and judged within) them
    args.within = problems.within
    fam = problems.family.numpy()
    ref_folder = args.reference or Path(kinlearn.__file__).parent / "checkpoints" / args.robot
    reference = kinlearn.Planner.load(ref_folder, body=body)  # every plan checked as it is judged
    has_retreat = "retreat" in inspect.signature(kinlearn.Planner.__init__).parameters
    ref_alone = kinlearn.Planner.load(ref_folder, retreat=False, body=body) if has_retreat else reference
    if args.candidates is None:  # trained as the network it is compared with
        args.candidates = reference.obstacle_tm.config.candidates
    ref_ok = success(reference, problems, body, refine_steps=0)
    ref_alone_ok = success(ref_alone, problems, body, refine_steps=0)
    line_ok = obstacle_outcome(
        body,
        [joint_line_path(*problems.problem(i), body=body)[0] for i in range(len(problems))],
        problems,
    )["success"].numpy()
    rows, summary = [], {}
    for f in args.families:
        if f not in FAMILIES:
            raise SystemExit(f"unknown family {f!r}")
        mine = fam == FAMILIES.index(f)
        net = train(args.robot, f, args, args.run_root / f"without-{f}")
        planner = planner_with(net, args.robot, args.run_root / f"planner-without-{f}", body)
        assert f not in planner.obstacle_tm.families, planner.obstacle_tm.families
        fixed = success(planner, problems, body, refine_steps=0)
        if has_retreat:  # the same folder again, without the retreat stage
            alone = kinlearn.Planner.load(args.run_root / f"planner-without-{f}", retreat=False, body=body)
            alone_ok = success(alone, problems, body, refine_steps=0)
        else:
            alone_ok = fixed
        timed = success(planner, problems, body, deadline=args.deadline)
        summary[f] = {
            "left_out_fixed": float(fixed[mine].mean()),
            "left_out_network_alone": float(alone_ok[mine].mean()),
            "seen_fixed": float(fixed[~mine].mean()),
            "line": float(line_ok[mine].mean()),
            "reference_fixed": float(ref_ok[mine].mean()),
            "reference_network_alone": float(ref_alone_ok[mine].mean()),
            "left_out_deadline": float(timed[mine].mean()),
            "trained_on": list(planner.obstacle_tm.families),
            "n": int(mine.sum()),
        }
        s = summary[f]
        rows.append(
            [
                f,
                f"{100 * s['left_out_fixed']:.0f}%",
                f"{100 * s['left_out_network_alone']:.0f}%",
                f"{100 * s['seen_fixed']:.1f}%",
                f"{100 * s['line']:.0f}%",
                f"{100 * s['reference_fixed']:.0f}% ({100 * s['reference_network_alone']:.0f}%)",
                f"{100 * s['left_out_deadline']:.0f}%",
            ]
        )
        print(
            f"  {f}: left out {rows[-1][1]} (alone {rows[-1][2]}), seen {rows[-1][3]}, deadline {rows[-1][6]}",
            flush=True,
        )
    keys = (
        "left_out_fixed",
        "left_out_network_alone",
        "seen_fixed",
        "reference_fixed",
        "reference_network_alone",
    )
    mean = {k: float(np.mean([s[k] for s in summary.values()])) for k in keys}
    summary["_mean"] = mean
    table = markdown_table(
        [
            "left-out family",
            "fixed time, left out",
            "network alone, left out",
            "fixed time, the families it saw",
            "joint line",
            "network that saw it (alone)",
            f"deadline {args.deadline:g} s, left out",
        ],
        rows,
    )
    print()
    print(table)
    print(f"\nmean over the left-out families: {100 * mean['left_out_fixed']:.1f}% left out "
          f"({100 * mean['left_out_network_alone']:.1f}% the network alone), against "
          f"{100 * mean['reference_fixed']:.1f}% ({100 * mean['reference_network_alone']:.1f}%) "
          "for the network that saw them")  # fmt: skip
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    (out / "table.md").write_text(table + "\n")
    print(f"wrote {out}/summary.json, table.md")
    write_result(
        f"leave_one_out_{args.robot}",
        {
            "left out": from_markdown(
                table, caption=f"{args.candidates}-candidate networks, {args.iterations} iterations each."
            ),
            "mean over the left-out families": {k: round(v, 4) for k, v in mean.items()},
        },
        title=f"A family left out of the obstacle network's training ({args.robot})",
        threads=1,
    )


if __name__ == "__main__":
    main()
