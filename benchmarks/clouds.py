"""Planning among point clouds: held-out problems of the seven scene families rendered as clouds two ways,
each beside the same problems given as primitives, every plan judged on the TRUE primitives.

    OMP_NUM_THREADS=1 python benchmarks/clouds.py [--robots panda ur5] [--per-family 3] [--radius 0.01]
        [--resolution 0.02] [--build-sizes 100000 1000000] [--spacing 0.01]

Renderings (:mod:`kinlearn.collision.cloud_render`):

- **surface**: every primitive's surface sampled on a 1 cm grid (``--spacing``), 2 mm Gaussian noise per
  axis (a fused scan: nothing occluded);
- **depth camera**: one pinhole camera, 320 × 240 pixels over 75° horizontally, 2 mm depth noise, placed
  over the robot's shoulder (0.35 m behind the base, 1.2 m up, looking at the obstacles' centre), the
  robot's own body at the start in view (its points removed by self-filtering at the start, its
  default margin); the floor is given as a plane (its hits dropped), the hidden sides of every obstacle are
  missing: **unknown space is free** to the planner, and the rows count the plans that collide with the
  true primitives there;
- **two depth cameras, fused**: the same camera and a second one 1.2 m to the side of the obstacles
  (:func:`side_camera`), each cloud given in its own camera's frame, fused by ``Scene.from_points`` (what
  one camera cannot see, the other may).

Each point is a ball of ``--radius`` (m; a row says where not), checked exactly: through the compiled grid of
``--resolution`` (m) first, then, for the body spheres the grid cannot clear, the points themselves; points
beyond the body's reach are cropped. Every plan is the default ``plan()`` (the learned proposals, which
read no cloud, then the retreat stage and RRT-Connect on the compiled check) at batch 1 on one thread, timed
with the cloud's grid already built (the build times are their own rows). A problem's ends may collide
with a cloud where they do not with the primitives (the held-out goals lie within millimetres of the
obstacles; a point's ball and the noise reach further): an end the balls touch with no point deeper inside
the arm than the cloud's contact depth (6 mm) is taken to touch the surface
(:mod:`kinlearn.collision.cloud_contact`), a deeper one refused. Success is given over all problems and
over those whose start and goal are free under the cloud (``ends free``).

Columns: problems, plans that succeed (flagged collision-free by the planner and successful on the true
primitives), success among problems whose ends are free under that rendering, plans flagged
collision-free that collide with the true primitives (and, for the depth renderings, those of them whose
deepest sphere sinks into a surface a camera saw, :func:`seen_where_it_collides`: a collision through the
gaps between its points, not in space no camera saw), successful plans whose timed trajectory
(``plan.timed()``, what a robot executes) sinks more than 1 mm into the true primitives, densely checked
as ``executable.py`` checks it (and those that cannot be timed), p50 plan time of the solved plans and, over the
problems solved both ways, its ratio to the same problems' p50 among the primitives, mean points per
cloud. A third rendering takes the depth camera's occluded space as occupied, 1 m behind every point it
sees, the arm's own included (self-filtering comes after the shadows): ``Scene.from_points(..., shadow=1.0)``.
Four more rows plan on the surface clouds: without the obstacle network; with balls of
:data:`SMALL_RADIUS` instead of ``--radius`` (the trade of a smaller ball: more goals read free, a sparser
or noisier cloud is covered less); with every end the balls touch refused (``contact=0``); and self-filtered at the goal as well as the start
(``self_filter=(body, [start, goal])``: the goal vouched for by the user, the points its body hides
dropped, so the plan is blind to the surface they sampled; the row counts what that costs).
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
import warnings

import numpy as np
import torch
from _common import header, markdown_table, table, write_result
from executable import DEPTH, executed_depth

import kinlearn
from kinlearn import Scene, load_robot
from kinlearn.collision import kernel
from kinlearn.collision.cloud import Cleaning, PointCloud
from kinlearn.collision.cloud_render import DepthCamera, surface_points
from kinlearn.data.problems import FAMILIES, ProblemSet
from kinlearn.errors import TimingError
from kinlearn.evaluation.obstacles import obstacle_outcome
from kinlearn.planning.planner import DEFAULT_CHECKPOINTS

DATA = __import__("pathlib").Path(__file__).parent / "data"


def camera_for(scene: Scene) -> DepthCamera:
    """The over-the-shoulder camera looking at the centre of the scene's primitives."""
    centres = np.array([p.centre for p in scene.primitives() if hasattr(p, "centre")])
    c = centres.mean(axis=0)
    xy = c[:2] / max(np.linalg.norm(c[:2]), 1e-9)
    position = (-0.35 * xy[0], -0.35 * xy[1], 1.2)
    return DepthCamera(position=position, target=tuple(c), width=320, height=240, fov=75.0, noise=0.002)


def side_camera(scene: Scene) -> DepthCamera:
    """A second camera, 1.2 m to the side of the primitives' centre (left of the way from the base to it)
    and 1.2 m up, looking at it: what the over-the-shoulder camera cannot see, it may."""
    first = camera_for(scene)
    c = np.asarray(first.target)
    xy = c[:2] / max(np.linalg.norm(c[:2]), 1e-9)
    position = (c[0] - 1.2 * xy[1], c[1] + 1.2 * xy[0], 1.2)
    return DepthCamera(position=position, target=first.target, width=320, height=240, fov=75.0, noise=0.002)


#: The row of the two depth cameras' views fused (over the shoulder and from the side).
TWO_VIEWS = "two depth cameras, fused"

#: The renderings, each a row: how the scene is seen, and how far behind a seen surface space counts as
#: occupied (m; 0: unknown space is free).
RENDERINGS = {
    "surface": 0.0,
    "depth camera": 0.0,
    TWO_VIEWS: 0.0,
    "depth camera, occluded space occupied": 1.0,
}


#: The row of the surface clouds planned without the obstacle network.
NO_NETWORK = "surface, no obstacle network"
#: The row of the surface clouds whose points are balls of SMALL_RADIUS (m).
SMALL = "surface, 5 mm balls"
SMALL_RADIUS = 0.005
#: The row of the surface clouds whose ends the balls touch are refused (``contact=0``).
REFUSED = "surface, ends the balls touch refused (contact=0)"
#: The row of the surface clouds self-filtered at the goal too: the goal vouched for.
TRUSTED = "surface, goal vouched for (filtered there too)"


def cameras_of(kind: str, scene: Scene) -> list[DepthCamera]:
    """The cameras of a depth rendering ``kind`` of ``scene``."""
    return [camera_for(scene), side_camera(scene)] if kind == TWO_VIEWS else [camera_for(scene)]


def arm_spheres(body, q) -> np.ndarray:
    """The arm's spheres ``(M, 4)`` (x, y, z, r) at joints ``q``: what the cameras see of it."""
    with torch.no_grad():
        return torch.cat([body(torch.as_tensor(q)[None])[0], body.radii[:, None]], dim=1).numpy()


def seen_where_it_collides(kb, joints, truth: Scene, cameras, occluders) -> bool:
    """Whether a camera saw where a plan collides: the true surface at the plan's deepest sphere (its
    samples inside the sphere, or the 20 nearest), seen by one of ``cameras`` past the true primitives and
    the arm where the cloud was taken (``occluders``). A plan flagged free touches no point's ball, so a
    collision where a camera saw is one through the gaps between its points; elsewhere, one in space no
    camera saw."""
    q = np.asarray(joints, dtype=np.float64)
    dense = np.concatenate(
        [np.linspace(a, b, 50, endpoint=False) for a, b in itertools.pairwise(q)] + [q[-1:]]
    )
    per = kernel.clearances(kb, kernel.KernelScene.of(truth), dense, per_sphere=True)[2]
    i, m = np.unravel_index(int(np.argmin(per)), per.shape)
    c = kernel.centres(kb, dense[i : i + 1])[0, m]
    samples = surface_points(truth, spacing=0.003, noise=0.0, seed=0)
    d = np.linalg.norm(samples - c, axis=1)
    at = samples[d < kb.radii[m]] if (d < kb.radii[m]).any() else samples[np.argsort(d)[:20]]
    return any(bool(cam.sees(truth, at, occluders).any()) for cam in cameras)


def render(
    kind: str, scene: Scene, body, start, radius: float, resolution: float, seed: int, goal=None,
    spacing: float = 0.01, contact: float | None = None,
) -> Scene:  # fmt: skip
    """The problem's scene as a cloud (its floor kept as a plane; surfaces sampled every ``spacing`` m),
    self-filtered at the start (the default margin: the cloud is taken where the robot stands; with a
    ``goal``, at the goal too) and cropped to the body's reach."""
    clean = Cleaning()
    start = start.numpy()
    if kind == "surface":
        pts = surface_points(scene, spacing=spacing, noise=0.002, seed=seed)
        at = start if goal is None else np.stack([start, goal.numpy()])
        return Scene.from_points(
            pts,
            radius=radius,
            resolution=resolution,
            cleaning=clean,
            self_filter=(body, at),
            floor=scene.floor,
            contact=contact,
        )
    robot_spheres = arm_spheres(body, start)
    cameras = cameras_of(kind, scene)
    views, poses = [], []
    for k, camera in enumerate(cameras):
        T = camera.pose()
        pts = camera.points(scene, spheres=robot_spheres, seed=seed + 100_000 * k)
        views.append((pts - T[:3, 3]) @ T[:3, :3])  # as the camera gives them
        poses.append(T)
    return Scene.from_points(
        views[0] if len(views) == 1 else views,
        frame=poses[0] if len(poses) == 1 else poses,
        radius=radius,
        resolution=resolution,
        cleaning=clean,
        self_filter=(body, start),
        shadow=RENDERINGS[kind],
        floor=scene.floor,
        contact=contact,
    )


def plan(planner, start, goal, scene):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        p = planner.plan(start, goal, obstacles=scene)
        return time.perf_counter() - t0, torch.as_tensor(p.joints), bool(p.collision_free), str(p.stage), p


def executed(p, body, truth: Scene) -> str:
    """What a robot would execute of a successful plan ``p``: its :meth:`~kinlearn.Plan.timed` trajectory
    checked densely against the TRUE primitives (``executable.py``'s check): "collides" (deeper than
    ``DEPTH``), "untimed", "free"; "" for a plan that did not succeed."""
    if not bool(p.success):
        return ""
    try:
        q = p.timed().q
    except TimingError:
        return "untimed"
    return "collides" if executed_depth(body, q, truth) > DEPTH else "free"


def build_times(sizes: list[int], radius: float, resolution: float) -> list[list]:
    """Grid build times (ms; the best of three, one thread) for clouds of ``sizes`` points: a table-family
    scene's surfaces sampled densely enough, then that many drawn (the grid's size is its extent's)."""
    ps = ProblemSet.load(DATA / "scene_problems_panda.npz", robot="panda")
    i = int(np.flatnonzero(ps.family.numpy() == FAMILIES.index("table"))[0])
    scene = ps.problem(i)[2]
    rows = []
    for n in sizes:
        pts = surface_points(scene, spacing=0.002, noise=0.002, seed=0)
        pts = pts[np.random.default_rng(0).choice(len(pts), n, replace=len(pts) < n)]
        _ = PointCloud(pts[:100], radius, resolution).packed  # compiled
        wall, cpu = [], []
        for _ in range(3):
            cloud = PointCloud(pts, radius, resolution)
            t0, c0 = time.perf_counter(), time.thread_time()
            cloud.packed  # noqa: B018 - builds the grid
            cpu.append(time.thread_time() - c0)
            wall.append(time.perf_counter() - t0)
        rows.append([n, "×".join(map(str, cloud.shape)), round(min(cpu) * 1e3, 1), round(min(wall) * 1e3, 1)])
        print(f"  {n} points: grid {cloud.shape}, {min(cpu) * 1e3:.1f} ms CPU, {min(wall) * 1e3:.1f} ms wall")
    return rows


def figure(path, rname: str = "panda", family: str = "table", radius: float = 0.01, resolution: float = 0.02):
    """One held-out problem among its depth camera's points: the points, the plan's end-effector path and
    the arm's spheres at its start and goal."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from kinlearn.body.kinematics import kinematics

    problems = ProblemSet.load(DATA / f"scene_problems_{rname}.npz", robot=rname)
    robot = load_robot(rname)
    body = problems.body(robot).double()
    planner = kinlearn.Planner.load(DEFAULT_CHECKPOINTS / rname, body=body)
    fam = problems.family.numpy()
    for i in np.flatnonzero(fam == FAMILIES.index(family)):
        start, goal, scene = problems.problem(int(i))
        cloud = render("depth camera", scene, body, start[: robot.dof].double(), radius, resolution, int(i))
        _t, joints, free, stage, _ = plan(planner, start, goal, cloud)
        if free:
            break
    pts = cloud.cloud.points
    pts = pts[np.random.default_rng(0).choice(len(pts), min(len(pts), 6000), replace=False)]
    dense = torch.cat([torch.lerp(a, b, torch.linspace(0, 1, 20, dtype=a.dtype)[:, None]) for a, b in
                       itertools.pairwise(joints)])  # fmt: skip
    ee = kinematics(robot, "fast").position(dense.double()).numpy()
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    ax.scatter(*pts.T, s=1, c=pts[:, 2], cmap="viridis", alpha=0.5, label="depth camera points")
    ax.plot(*ee.T, color="crimson", lw=2, label=f"end-effector path ({stage})")
    for q, colour, name in ((joints[0], "tab:blue", "start"), (joints[-1], "tab:orange", "goal")):
        c = body(q.double()[None])[0].detach().numpy()
        ax.scatter(
            *c.T, s=(body.radii.numpy() * 400) ** 2 / 10, color=colour, alpha=0.35, label=f"arm at {name}"
        )
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.set_box_aspect((1, 1, 0.8))
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(f"{rname}, a held-out {family} problem among {cloud.cloud.num_points} points")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robots", nargs="*", default=["panda", "ur5"])
    ap.add_argument("--per-family", type=int, default=3, help="held-out problems per family (the first ones)")
    ap.add_argument("--radius", type=float, default=0.01)
    ap.add_argument("--resolution", type=float, default=0.02)
    ap.add_argument("--build-sizes", type=int, nargs="*", default=[100_000, 1_000_000])
    ap.add_argument("--spacing", type=float, default=0.01, help="the surface rendering's sample spacing (m)")
    ap.add_argument("--no-write", action="store_true", help="print only")
    ap.add_argument("--figure", action="store_true", help="only draw docs/figures/cloud_plan.png")
    args = ap.parse_args()
    if args.figure:
        figure(__import__("pathlib").Path(__file__).parents[1] / "docs" / "figures" / "cloud_plan.png")
        return
    torch.set_num_threads(1)
    print(header("Planning among point clouds", 1))
    figures: dict = {}
    rows, summary = [], {}
    for rname in args.robots:
        problems = ProblemSet.load(DATA / f"scene_problems_{rname}.npz", robot=rname)
        fam = problems.family.numpy()
        idx = [int(i) for f in FAMILIES for i in np.flatnonzero(fam == FAMILIES.index(f))[: args.per_family]]
        subset = problems[idx]
        robot = load_robot(rname)
        body = problems.body(robot).double()
        planner = kinlearn.Planner.load(DEFAULT_CHECKPOINTS / rname, body=body)
        planner.warm_up()
        # the obstacle network reads no cloud: the same planner without it, on the surface clouds, says
        # what its blind proposals are worth there
        bare = kinlearn.Planner.load(DEFAULT_CHECKPOINTS / rname, body=body, obstacle_tm=None)
        bare.warm_up()
        kb = kernel.KernelBody.of(body)
        s0, g0, sc0 = subset.problem(0)
        sc0 = render(
            "surface", sc0, body, s0[: robot.dof], args.radius, args.resolution, 0, spacing=args.spacing
        )
        plan(planner, s0, g0, sc0)
        result = {k: {"paths": [], "t": [], "flag": [], "ends": [], "points": [], "stage": [], "executed": []} for k in
                  ("primitives", *RENDERINGS, NO_NETWORK, SMALL, REFUSED, TRUSTED)}  # fmt: skip
        for n in range(len(subset)):
            start, goal, scene = subset.problem(n)
            q = torch.stack([start[: robot.dof], goal[: robot.dof]]).double()
            for kind in result:
                if kind == "primitives":
                    sc = scene
                elif kind == SMALL:
                    sc = render(
                        "surface", scene, body, q[0], SMALL_RADIUS, args.resolution, n, spacing=args.spacing
                    )
                    sc.cloud.packed  # noqa: B018 - the grid built before the clock starts
                elif kind == REFUSED:
                    sc = render(
                        "surface", scene, body, q[0], args.radius, args.resolution, n, spacing=args.spacing,
                        contact=0.0,
                    )  # fmt: skip
                    sc.cloud.packed  # noqa: B018 - the grid built before the clock starts
                elif kind == TRUSTED:
                    sc = render(
                        "surface",
                        scene,
                        body,
                        q[0],
                        args.radius,
                        args.resolution,
                        n,
                        goal=q[1],
                        spacing=args.spacing,
                    )
                    sc.cloud.packed  # noqa: B018 - the grid built before the clock starts
                elif kind != NO_NETWORK:  # (the no-network row plans on the surface cloud just made)
                    sc = render(
                        kind, scene, body, q[0], args.radius, args.resolution, n, spacing=args.spacing
                    )
                    sc.cloud.packed  # noqa: B018 - the grid built before the clock starts
                    if kind == "surface":
                        surface = sc
                else:
                    sc = surface
                d, s = kernel.clearances(kb, kernel.KernelScene.of(sc), q.numpy())
                t, joints, free, stage, p = plan(bare if kind == NO_NETWORK else planner, start, goal, sc)
                r = result[kind]
                r["executed"].append(executed(p, body, scene))
                r["paths"].append(joints)
                r["t"].append(t)
                r["flag"].append(free)
                r["stage"].append(stage)
                r["ends"].append(bool((d > 0).all() and (s > 0).all()))
                r["points"].append(0 if sc.cloud is None else sc.cloud.num_points)
            print(
                f"  {rname} {n:3d} {FAMILIES[int(subset.family[n])]:9s} "
                + "  ".join(
                    f"{k[:5]}{k[-5:]}: {'free' if result[k]['flag'][-1] else 'NOT '} {result[k]['t'][-1] * 1e3:6.1f} ms"
                    f" ({result[k]['stage'][-1]}{'' if result[k]['ends'][-1] else ', ends collide'})"
                    for k in result
                ),
                flush=True,
            )
        prim_ok = obstacle_outcome(body, result["primitives"]["paths"], subset)["success"].numpy()
        prim_ok &= np.array(result["primitives"]["flag"])
        for kind, r in result.items():
            out = obstacle_outcome(body, r["paths"], subset)
            free_true = out["collision_free"].numpy()
            flag = np.array(r["flag"])
            ok = out["success"].numpy() & flag  # the planner's own verdict too: a flagged plan failed
            ends = np.array(r["ends"])
            wrong = int((flag & ~free_true).sum())
            seen = None  # of the colliding plans, those colliding where a camera saw (depth renderings)
            if "camera" in kind:
                seen = 0
                for n in np.flatnonzero(flag & ~free_true):
                    start, _, scene = subset.problem(int(n))
                    occluders = arm_spheres(body, start[: robot.dof].double())
                    seen += seen_where_it_collides(
                        kb, r["paths"][n], scene, cameras_of(kind, scene), occluders
                    )
            t = np.array(r["t"])
            both = ok & prim_ok  # the time of the same problems, solved both ways
            t_prim = np.array(result["primitives"]["t"])
            ratio = float(np.median(t[both]) / np.median(t_prim[both])) if both.any() else float("nan")
            summary[f"{rname} {kind}"] = {
                "problems": len(ok),
                "success": float(ok.mean()),
                "ends_free": int(ends.sum()),
                "success_ends_free": float(ok[ends].mean()) if ends.any() else None,
                "flagged_free_but_colliding": wrong,
                "colliding_where_a_camera_saw": seen,
                "timed_colliding_as_executed": r["executed"].count("collides"),
                "timed_untimed": r["executed"].count("untimed"),
                "p50_ms": float(np.median(t[ok]) * 1e3) if ok.any() else None,
                "p50_ratio_solved_both": ratio if both.any() else None,
                "solved_both": int(both.sum()),
                "mean_points": float(np.mean(r["points"])),
                "stages": {s: r["stage"].count(s) for s in sorted(set(r["stage"]))},
            }
            rows.append(
                [
                    rname,
                    kind,
                    len(ok),
                    f"{100 * ok.mean():.1f}%",
                    f"{100 * ok[ends].mean():.1f}% of {int(ends.sum())}" if ends.any() else "",
                    wrong,
                    "" if seen is None else seen,
                    f"{r['executed'].count('collides')} ({r['executed'].count('untimed')} untimed)",
                    f"{np.median(t[ok]) * 1e3:.1f}" if ok.any() else "",
                    f"{ratio:.2f} ({int(both.sum())})" if both.any() else "",
                    f"{np.mean(r['points']):.0f}",
                ]
            )
    columns = ["robot", "scene as", "problems", "success", "success, ends free", "flagged free but colliding",
               "of which where a camera saw", "timed, colliding as executed", "p50 ms (solved)", "p50 / primitives (solved both)", "points"]  # fmt: skip
    print()
    print(markdown_table(columns, rows))
    print("per row (stages that made the plans):", json.dumps(summary, indent=1))
    caption = (
        f"The first {args.per_family} held-out problems of each of the seven families per arm, default plan(), "
        f"surfaces sampled every {args.spacing} m, points as balls of {args.radius} m (a row says where not), "
        "checked exactly through a grid of "
        f"{args.resolution} m and the points; judged on the true primitives. Depth camera: unknown (occluded) "
        "space is free to the planner, unless the row takes it as occupied."
    )
    figures["planning among clouds"] = table(columns, rows, caption=caption)
    if args.build_sizes:
        print("\ngrid build times (one thread):")
        brows = build_times(args.build_sizes, args.radius, args.resolution)
        bcols = ["points", "grid cells", "build ms (CPU)", "build ms (wall)"]
        print(markdown_table(bcols, brows))
        figures["grid build"] = table(
            bcols,
            brows,
            caption=f"A table-family scene's surfaces (~1.2 m across) at {args.resolution} m cells.",
        )
    if not args.no_write:
        write_result("clouds", figures, title="Planning among point clouds", threads=1)


if __name__ == "__main__":
    main()
