"""Arms onboarded from their URDFs: fitted collision spheres against the shipped hand-made ones, and planning
with arms whose spheres were fitted, judged again against their own collision meshes.

    python benchmarks/onboard.py [--spheres panda ur5 xarm7 z1] [--plan xarm7 z1] [--onboarded runs/onboard/ur10]
        [--compare panda] [--per-family 10] [--points 20000]

Spheres (``--spheres``): per arm, on ``--points`` points drawn afresh on each link's collision surface
(example-robot-data's meshes, area-weighted; seed 99, not a fitting seed), the sphere count, the share of points
inside a sphere, the points more than 2 mm outside every sphere, the farthest one, and the volume of the
spheres' union outside the link's solid (voxelised, Monte Carlo), summed over the links. For the panda and the
ur5 both the shipped spherized URDFs (VAMP's, made with another tool) and spheres fitted now by
:func:`kinlearn.collision.spherize.spherize` (seed 0, default settings); for the xarm7 and the z1 the shipped
fitted bodies (``robots/<arm>/``); for an arm of an ``--onboarded`` run, named here too, the spheres it fitted.

Planning (``--plan`` arms with a shipped obstacle network, ``--onboarded`` run directories of ``kinlearn
onboard``): ``--per-family`` held-out problems of each of the seven scene families (seeds 1004–1010, the
held-out seeds; unverified, then kept where the compiled RRT-Connect solves them within 20,000 iterations), each
planned at batch 1 by the default ``plan()``; success, and among the plans called successful those whose path
collides with the URDF's collision meshes (coal, every 0.01 rad: :func:`kinlearn.collision.mesh.mesh_check`).

``--compare ARM`` (panda or ur5): the shipped planner on its held-out scene problems
(``benchmarks/data/scene_problems_panda.npz``, ``scene_problems_ur5_arm.npz``: the first ``--per-family`` of each
family) checking with the shipped spheres (the ur5's arm alone, as example-robot-data's ur5 has no gripper) and
with spheres fitted now, each plan checked against the meshes.
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np
import torch
from _common import RUNS, table, write_result

from kinlearn import load_robot
from kinlearn.body.robot import BUILTIN_ROBOTS
from kinlearn.collision.body import BodySpheres, _default_pairs, always_overlapping, body_spheres
from kinlearn.collision.mesh import MeshBody, mesh_check
from kinlearn.collision.spherize import (
    SpherizeConfig,
    coverage,
    excess_volume,
    link_geometry,
    spherize,
)
from kinlearn.data.problems import FAMILIES, ProblemConfig, ProblemSet, make_problems
from kinlearn.errors import PlanningError
from kinlearn.planning.planner import Planner
from kinlearn.training.obstacle_path import expert_paths

SCENE_FAMILIES = ("bookcase", "cubby", "cage", "bin", "table", "wall", "clutter")
HELDOUT_SEEDS = {f: 1001 + FAMILIES.index(f) for f in SCENE_FAMILIES}
DATA = Path(__file__).resolve().parent / "data"


def sphere_figures(spheres: np.ndarray, robot, points: int) -> dict:
    """Count, coverage and excess of ``spheres`` rows [link, x, y, z, r] against ``robot``'s URDF geometry."""
    inside = beyond = total = 0
    farthest = excess = solid = 0.0
    worst = 100.0
    for g in link_geometry(robot):
        if not g.parts:
            continue
        s = spheres[spheres[:, 0] == g.index, 1:]
        pts = g.sample(points, np.random.default_rng([99, g.index]))
        if len(s) == 0:
            beyond += len(pts)
            total += len(pts)
            worst = 0.0
            continue
        cov = coverage(s, pts, tolerance=0.002)
        inside += round(cov["inside"] * len(pts))
        worst = min(worst, 100.0 * cov["inside"])
        beyond += cov["beyond_tolerance"]
        total += len(pts)
        farthest = max(farthest, cov["farthest_outside"])
        ex = excess_volume(s, g)
        excess += ex["excess"]
        solid += ex["solid"]
    return {
        "spheres": len(spheres),
        "coverage_pct": 100.0 * inside / total,
        "worst_link_coverage_pct": worst,
        "beyond_2mm": beyond,
        "points": total,
        "farthest_mm": 1e3 * farthest,
        "excess_l": 1e3 * excess,
        "solid_l": 1e3 * solid,
    }


def _rows(body) -> np.ndarray:
    return np.concatenate(
        [
            body.link[:, None].double().numpy(),
            body.local.double().numpy(),
            body.radii[:, None].double().numpy(),
        ],
        1,
    )


def sphere_table(arms, points: int) -> tuple[dict, list]:
    rows, out = [], {}
    for name in arms:
        robot = load_robot(name)
        sets = {}
        if name in ("panda", "ur5"):
            sets["shipped (VAMP)"] = _rows(body_spheres(robot))
            t0 = time.perf_counter()
            fit = spherize(robot, config=SpherizeConfig())
            sets[f"fitted ({time.perf_counter() - t0:.0f} s)"] = fit.spheres
        else:  # an arm kinlearn ships, or one a `kinlearn onboard` run registered (--onboarded)
            shipped = name in BUILTIN_ROBOTS
            sets["fitted (shipped)" if shipped else "fitted (onboarded)"] = _rows(body_spheres(robot))
        for label, s in sets.items():
            f = sphere_figures(s, robot, points)
            out[f"{name} {label}"] = f
            rows.append(
                [
                    name,
                    label,
                    f["spheres"],
                    round(f["coverage_pct"], 3),
                    round(f["worst_link_coverage_pct"], 3),
                    f["beyond_2mm"],
                    round(f["farthest_mm"], 2),
                    round(f["excess_l"], 2),
                    round(f["solid_l"], 2),
                ]
            )
            print(rows[-1], flush=True)
    return out, rows


def fitted_body_of(robot) -> BodySpheres:
    """A body of spheres fitted now to ``robot``'s URDF, with the body's self-collision rule (links two apart,
    less pairs overlapping nearly always, less the link pairs the fit found touching everywhere)."""
    fit = spherize(robot)
    link = fit.spheres[:, 0].astype(np.int64)
    pairs = _default_pairs(link)
    ends = np.sort(link[pairs], axis=1)
    pairs = pairs[
        np.array([(int(a), int(b)) not in set(fit.excluded_link_pairs) for a, b in ends], dtype=bool)
    ]
    kept, _ = always_overlapping(robot, fit.spheres, pairs)
    return BodySpheres(robot, fit.spheres, kept, name="fitted")


def heldout(robot, per_family: int, out: Path) -> Path:
    """Held-out problems of the seven families for ``robot`` (unverified), saved once under ``out``; a family
    none of whose problems can be made (no valid start and goal in 400 scenes) is left out and named in
    ``<file>.missing.txt``."""
    path = out / f"heldout_{robot.name}_{per_family}.npz"
    if not path.is_file():
        sets, missing = [], []
        for f in SCENE_FAMILIES:
            try:
                sets.append(
                    make_problems(
                        f,
                        per_family,
                        HELDOUT_SEEDS[f],
                        robot=robot,
                        config=ProblemConfig(verify=False, max_attempts=400),
                    )
                )
            except PlanningError:
                missing.append(f)
        path.with_suffix(".missing.txt").write_text(" ".join(missing) + "\n")
        ProblemSet.concat(sets).save(path)
    return path


def plan_figures(planner: Planner, mesh: MeshBody, pset: ProblemSet, keep: np.ndarray) -> dict:
    ok = flagged_free_collides = 0
    times = []
    per_family = {}
    for i in np.flatnonzero(keep):
        start, goal, scene = pset.problem(int(i))
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            plan = planner.plan(start.double(), goal.double(), obstacles=scene.to(torch.float64))
        times.append(time.perf_counter() - t0)
        fam = SCENE_FAMILIES[[FAMILIES.index(f) for f in SCENE_FAMILIES].index(int(pset.family[i]))]
        f = per_family.setdefault(fam, [0, 0])
        f[1] += 1
        if bool(plan.success):
            ok += 1
            f[0] += 1
            if not bool(mesh_check(mesh, plan.joints.double(), scene.to(torch.float64))):
                flagged_free_collides += 1
    n = int(keep.sum())
    return {
        "problems": n,
        "success_pct": 100.0 * ok / max(n, 1),
        "flagged_free_colliding_with_meshes": flagged_free_collides,
        "p50_ms": 1e3 * float(np.median(times)) if times else None,
        "per_family": {k: f"{a}/{b}" for k, (a, b) in per_family.items()},
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spheres", nargs="*", default=["panda", "ur5", "xarm7", "z1"])
    ap.add_argument("--plan", nargs="*", default=["xarm7", "z1"])
    ap.add_argument("--onboarded", nargs="*", type=Path, default=[])
    ap.add_argument("--compare", nargs="*", default=[])
    ap.add_argument("--per-family", type=int, default=10)
    ap.add_argument("--points", type=int, default=20000)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--result", default="onboard_planning", help="the planning figures' result name")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    out = RUNS / "onboard"
    out.mkdir(parents=True, exist_ok=True)
    figures: dict = {}
    if args.onboarded:  # registered first, so that --spheres may name them too
        from kinlearn.training.onboard import load_onboarded

        for run_dir in args.onboarded:
            load_onboarded(run_dir)
    if args.spheres:
        _, rows = sphere_table(args.spheres, args.points)
        figures["spheres"] = table(
            [
                "arm",
                "spheres",
                "count",
                "coverage %",
                "worst link %",
                "points > 2 mm out",
                "farthest out (mm)",
                "excess (L)",
                "solid (L)",
            ],
            rows,
            caption=f"{args.points} fresh surface points per link (seed 99); excess: the union outside the voxelised solid",
        )
    plan_rows = []
    arms = [(name, None) for name in args.plan] + [(None, d) for d in args.onboarded]
    for name, run_dir in arms:
        if run_dir is not None:
            from kinlearn.training.onboard import load_onboarded

            robot = load_onboarded(run_dir)
            planner = Planner.load(run_dir / "planner")
        else:
            robot = load_robot(name)
            planner = Planner.default(name)
        mesh = MeshBody(robot)
        path = heldout(robot, args.per_family, out)
        pset = ProblemSet.load(path, robot=robot.name)
        _, found = expert_paths(path, robot, 10)
        keep = found.numpy().astype(bool)
        f = plan_figures(planner, mesh, pset, keep)
        f["generated"] = len(pset)
        missing = path.with_suffix(".missing.txt")
        f["families_not_generated"] = missing.read_text().split() if missing.is_file() else []
        if (
            run_dir is not None and (run_dir / "steps.json").is_file()
        ):  # how long onboarding it took, per step
            import json

            steps = json.loads((run_dir / "steps.json").read_text())
            f["onboard_seconds"] = {k: round(v["seconds"], 1) for k, v in steps.items()}
            f["onboard_size"] = json.loads((run_dir / "config.json").read_text()).get("onboard", {})
        figures[f"plan {robot.name}"] = f
        plan_rows.append(
            [
                robot.name,
                len(pset),
                f["problems"],
                round(f["success_pct"], 1),
                f["flagged_free_colliding_with_meshes"],
                round(f["p50_ms"] or 0, 2),
            ]
        )
        print(plan_rows[-1], f["per_family"], flush=True)
    for name in args.compare:
        robot = load_robot(name)
        pset = ProblemSet.load(
            DATA / f"scene_problems_{name}{'_arm' if name == 'ur5' else ''}.npz", robot=name
        )
        keep = np.zeros(len(pset), dtype=bool)
        for fam in SCENE_FAMILIES:
            idx = np.flatnonzero(pset.family.numpy() == FAMILIES.index(fam))[: args.per_family]
            keep[idx] = True
        mesh = MeshBody(robot)
        fitted_body = fitted_body_of(robot)
        for label, body in (("shipped", body_spheres(robot)), ("fitted", fitted_body)):
            planner = Planner.default(name, body=body)
            f = plan_figures(planner, mesh, pset, keep)
            figures[f"compare {name} {label}"] = f
            plan_rows.append(
                [
                    f"{name} ({label} spheres)",
                    len(pset),
                    f["problems"],
                    round(f["success_pct"], 1),
                    f["flagged_free_colliding_with_meshes"],
                    round(f["p50_ms"] or 0, 2),
                ]
            )
            print(plan_rows[-1], f["per_family"], flush=True)
    if plan_rows:
        figures["planning"] = table(
            [
                "arm",
                "generated",
                "solvable (RRT-Connect)",
                "plan() success %",
                "successes colliding with meshes",
                "p50 ms",
            ],
            plan_rows,
            caption="held-out problems of the seven scene families; plan() default, batch 1; meshes checked with coal",
        )
    if "spheres" in figures:
        default = args.spheres == ["panda", "ur5", "xarm7", "z1"]
        write_result(
            "onboard_spheres" if default else "onboard_spheres_" + "_".join(args.spheres),
            {"spheres": figures.pop("spheres")},
            title="Collision spheres fitted to an arm's own meshes, beside the shipped ones"
            + ("" if default else f" ({', '.join(args.spheres)})"),
            notes="Coverage on fresh surface samples of each link's collision geometry (example-robot-data's meshes).",
            threads=args.threads,
        )
    if figures:
        write_result(
            args.result,
            figures,
            title="Planning with fitted sphere bodies, checked against the meshes: "
            + ", ".join(
                [
                    *args.plan,
                    *(d.name for d in args.onboarded),
                    *(f"{a} (shipped and fitted)" for a in args.compare),
                ]
            ),
            notes="Plans called successful checked again against the URDF's collision meshes (coal).",
            threads=args.threads,
        )


if __name__ == "__main__":
    main()
