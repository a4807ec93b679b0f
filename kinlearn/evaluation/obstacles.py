"""Judging plans around obstacles: the success rule, per-method summaries, the table and the figures.

The success rule (:func:`obstacle_outcome`) is the same for every planner, learned or not. A joint path
(executed by moving linearly in joint space between consecutive configurations) succeeds when

- it **starts at the problem's start** (every joint within :data:`START_TOLERANCE` rad),
- it **reaches the goal**: its last configuration within ``tolerance.joints`` rad of the goal's joints
  (every joint) and its end effector, by the analytic FK, within ``tolerance.position`` metres of the
  goal's end effector (1 cm and 0.05 rad by default, :data:`~kinlearn.planning.plan.DEFAULT_TOLERANCE`),
- every configuration is **within the joint limits** (to :data:`LIMIT_TOLERANCE` rad), and
- it is **collision-free**: :func:`~kinlearn.collision.check_path` with the robot's 12-sphere body and
  base (:func:`~kinlearn.collision.body_spheres`), at most 1 cm of sphere travel between checked
  configurations, finds no body–scene contact (floor included) and no self-collision.

The verdict is :func:`~kinlearn.planning.plan.judge`'s, the rule every plan is judged by; this module
adds what a benchmark reports beside it (each criterion apart, clearance, path lengths). Paths of
different lengths are padded by repeating their last configuration, which adds only zero-length
segments and so checks exactly the same configurations. A method that returned no path
(``None``) fails every criterion. matplotlib is imported only when a figure is drawn.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import torch

from ..body.kinematics import kinematics
from ..collision import BodySpheres, Scene, check_path
from ..collision.geometry import box_faces, cylinder_faces
from ..data.problem import LIMIT_TOLERANCE, Problem
from ..data.problems import FAMILIES, ProblemSet
from ..errors import ConfigError, ShapeError
from ..io import atomic_write
from ..planning.judge import judge
from ..planning.plan import DEFAULT_TOLERANCE, Tolerance
from ..planning.plan import START_TOLERANCE as PLAN_START_TOLERANCE
from .metrics import dense_path_length

__all__ = [
    "LIMIT_TOLERANCE",
    "OUTCOME_KEYS",
    "START_TOLERANCE",
    "format_table",
    "obstacle_outcome",
    "plot_obstacle_plans",
    "plot_success_latency",
    "summarize_outcome",
]

#: rad: a path's first configuration must equal the problem's start to this: judge's own tolerance
#: (:data:`kinlearn.planning.plan.START_TOLERANCE`; float32 round-off of joint angles passes).
START_TOLERANCE = PLAN_START_TOLERANCE
#: The per-problem tensors :func:`obstacle_outcome` returns.
OUTCOME_KEYS = (
    "success",
    "planned",
    "starts_at_start",
    "goal_reached",
    "within_limits",
    "collision_free",
    "self_collision",
    "clearance",
    "goal_error",
    "joint_error",
    "joint_length",
    "ee_length",
)

_F64 = torch.float64


def _problem_tensors(problems, dof: int) -> tuple[torch.Tensor, torch.Tensor, Scene]:
    if isinstance(problems, ProblemSet):
        return problems.start.to(_F64), problems.goal.to(_F64), problems.scene.to(_F64)
    try:
        start, goal, scene = problems
    except (TypeError, ValueError) as exc:
        raise ConfigError(
            "problems must be a ProblemSet or a tuple (start (N, dof), goal (N, dof), scene)"
        ) from exc
    if not isinstance(scene, Scene):
        raise ConfigError(
            f"the third element of problems must be a kinlearn Scene, got {type(scene).__name__}"
        )
    start = torch.as_tensor(start).detach().cpu().to(_F64)
    goal = torch.as_tensor(goal).detach().cpu().to(_F64)
    if start.ndim == 1:
        start, goal = start.unsqueeze(0), goal.unsqueeze(0)
    if start.ndim != 2 or start.shape[-1] != dof or goal.shape != start.shape:
        raise ShapeError(
            f"start and goal must both have shape (N, {dof}), got {tuple(start.shape)} and {tuple(goal.shape)}"
        )
    return start, goal, scene.to(_F64)


def _paths(joints, n: int, dof: int) -> list[torch.Tensor | None]:
    """The paths as a list of ``(K_i, dof)`` float64 tensors, ``None`` for a missing or non-finite one."""
    if isinstance(joints, (torch.Tensor, np.ndarray)):
        joints = torch.as_tensor(joints)
        if joints.ndim == 2 and n == 1:
            joints = joints.unsqueeze(0)
        if joints.ndim != 3:
            raise ShapeError(f"joint paths must have shape (N, T+1, {dof}), got {tuple(joints.shape)}")
        joints = list(joints)
    elif not isinstance(joints, Sequence):
        raise ShapeError("joints must be a tensor (N, T+1, dof) or a sequence of N paths (K_i, dof) or None")
    if len(joints) != n:
        raise ShapeError(f"got {len(joints)} paths for {n} problems")
    out: list[torch.Tensor | None] = []
    for i, p in enumerate(joints):
        if p is None:
            out.append(None)
            continue
        p = torch.as_tensor(p).detach().cpu()
        if p.ndim != 2 or p.shape[-1] != dof or p.shape[0] < 1:
            raise ShapeError(f"path {i} must have shape (K, {dof}) with K >= 1, got {tuple(p.shape)}")
        if not p.is_floating_point():
            raise ShapeError(f"path {i} must hold floating-point joint values, got {p.dtype}")
        p = p.to(_F64)
        out.append(p if bool(torch.isfinite(p).all()) else None)
    return out


def obstacle_outcome(
    body: BodySpheres,
    joints,
    problems,
    tolerance: Tolerance = DEFAULT_TOLERANCE,
    *,
    max_travel: float = 0.01,
    limits: tuple | None = None,
) -> dict[str, torch.Tensor]:
    """Judge ``N`` joint paths against their problems by the success rule (see the module docstring).
    ``limits``: ``(lower, upper)`` joint limits a path must keep within instead of the robot's; by default
    the robot's, or the body's for a :class:`~kinlearn.data.problems.ProblemSet` made within them
    (``ProblemSet.within == "body"``, ``ProblemConfig(within="body")``); the body's
    :attr:`~kinlearn.collision.BodySpheres.outer_limits` judge problems whose ends lie beyond the robot's own
    but within its model's (the standard benchmarks' panda), as the planner plans them.

    ``body``: :func:`~kinlearn.collision.body_spheres` of the robot (the 12-sphere body with the base).
    ``joints``: a tensor ``(N, T+1, dof)`` or a sequence of ``N`` paths ``(K_i, dof)`` (tensors or
    arrays; ``None`` for a method that found no path; a path holding NaN/inf counts as none).
    ``problems``: a :class:`~kinlearn.data.problems.ProblemSet` of ``N`` problems, or a tuple
    ``(start (N, dof), goal (N, dof), scene)`` with a scene of batch ``(N,)`` or one scene for all.

    Returns a dict of ``(N,)`` CPU tensors (:data:`OUTCOME_KEYS`): bool ``success`` (all of the
    following), ``planned`` (a finite path was given), ``starts_at_start``, ``goal_reached``,
    ``within_limits``, ``collision_free`` (scene and self), ``self_collision``; float64 ``clearance``
    (smallest body–scene signed distance over the checked configurations, m), ``goal_error``
    (end effector, m), ``joint_error`` (largest joint, rad), ``joint_length`` (Σ ‖Δθ‖₂ over the path's
    segments, rad) and ``ee_length`` (the executed end-effector path, sampled every 0.01 rad of joint
    motion, m). Float values are NaN where no path was planned.
    """
    robot = body.robot
    dof = robot.dof
    start, goal, scene = _problem_tensors(problems, dof)
    if limits is None and isinstance(problems, ProblemSet) and problems.within == "body":
        limits = body.limits
    n = start.shape[0]
    if len(scene.batch_shape) not in (0, 1) or (len(scene.batch_shape) == 1 and scene.batch_shape[0] != n):
        raise ShapeError(
            f"the scene must be unbatched or of batch ({n},), got batch {tuple(scene.batch_shape)}"
        )
    paths = _paths(joints, n, dof)
    planned = torch.tensor([p is not None for p in paths], dtype=torch.bool)
    nan = torch.full((n,), math.nan, dtype=_F64)
    out = {
        "success": torch.zeros(n, dtype=torch.bool),
        "planned": planned,
        "starts_at_start": torch.zeros(n, dtype=torch.bool),
        "goal_reached": torch.zeros(n, dtype=torch.bool),
        "within_limits": torch.zeros(n, dtype=torch.bool),
        "collision_free": torch.zeros(n, dtype=torch.bool),
        "self_collision": torch.zeros(n, dtype=torch.bool),
        "clearance": nan.clone(),
        "goal_error": nan.clone(),
        "joint_error": nan.clone(),
        "joint_length": nan.clone(),
        "ee_length": nan.clone(),
    }
    idx = torch.nonzero(planned).reshape(-1)
    if idx.numel() == 0:
        return out
    live = [paths[int(i)] for i in idx]
    longest = max(2, max(p.shape[0] for p in live))  # a single configuration is a path of no motion
    padded = torch.stack([torch.cat((p, p[-1:].expand(longest - p.shape[0], dof))) for p in live])
    s0, sT = start[idx], goal[idx]

    starts = (padded[:, 0] - s0).abs().amax(-1) <= START_TOLERANCE
    within = robot.within_limits(padded, LIMIT_TOLERANCE, limits=limits).all(-1)
    sc = scene[idx] if len(scene.batch_shape) else scene
    check = check_path(body, padded, sc, max_travel=max_travel)
    free = check.collision_free.cpu()
    # The verdict is judge's, the one rule every plan is judged by (given the dense check made here,
    # whose clearance and self-collision are reported too).
    kin = kinematics(robot, "fast")
    ef0, efT = kin.position(s0, validate=False), kin.position(sT, validate=False)
    # Ends beyond the robot's own limits but within its body's model's (or the given limits) make a problem
    # (the planner plans them); whether a path keeps within the limits is `within`, above.
    lo, hi = body.outer_limits
    if limits is not None:
        lo, hi = (
            np.minimum(lo, np.asarray(limits[0], np.float64)),
            np.maximum(hi, np.asarray(limits[1], np.float64)),
        )
    problem = Problem.from_states(
        robot.with_limits(lo, hi), torch.cat((s0, ef0), -1), torch.cat((sT, efT), -1), obstacles=sc
    )
    plan = judge(problem, padded, tolerance=tolerance, max_travel=max_travel, body=body, collision_free=free)
    goal_error, joint_error = plan.goal_error.to(_F64), plan.joint_error.to(_F64)
    goal_reached = (goal_error <= tolerance.position) & (joint_error <= tolerance.joints)

    out["starts_at_start"][idx] = starts
    out["goal_reached"][idx] = goal_reached
    out["within_limits"][idx] = within
    out["collision_free"][idx] = free
    out["self_collision"][idx] = check.self_collision.cpu()
    out["clearance"][idx] = check.clearance.cpu().to(_F64)
    out["goal_error"][idx] = goal_error
    out["joint_error"][idx] = joint_error
    out["success"][idx] = plan.success & within  # judge's verdict, within the limits given too
    out["joint_length"][idx] = torch.stack(
        [torch.linalg.vector_norm(p[1:] - p[:-1], dim=-1).sum() for p in live]
    )
    out["ee_length"][idx] = torch.stack(
        [dense_path_length(robot, p) if p.shape[0] > 1 else p.new_zeros(()) for p in live]
    )
    return out


# --------------------------------------------------------------------------------------------------
# Summaries and the table
# --------------------------------------------------------------------------------------------------


def _rate(x: torch.Tensor) -> float | None:
    return float(x.double().mean()) if x.numel() else None


def summarize_outcome(outcome: Mapping[str, torch.Tensor], seconds, problems: ProblemSet) -> dict:
    """One method's row: success rates, latency and path length over ``problems``.

    ``outcome``: from :func:`obstacle_outcome` for these problems; ``seconds (N,)``: each problem's
    wall time. Rates are fractions in [0, 1] (``None`` for an empty subset). ``joint_length_ratio``
    is the median over the successful paths of (joint path length / straight-line joint distance
    ‖θ_goal − θ_start‖), ``None`` when none succeeded. Latencies in milliseconds over all problems.
    """
    seconds = torch.as_tensor(seconds, dtype=_F64).reshape(-1)
    n = len(problems)
    if seconds.shape[0] != n or outcome["success"].shape[0] != n:
        raise ShapeError(
            f"outcome ({outcome['success'].shape[0]}), seconds ({seconds.shape[0]}) and problems ({n}) "
            "must have the same length"
        )
    ok = outcome["success"]
    hard = problems.hard
    by_family = {}
    for k, name in enumerate(FAMILIES):
        sel = problems.family == k
        if bool(sel.any()):
            by_family[name] = _rate(ok[sel])
    line = torch.linalg.vector_norm(problems.goal.to(_F64) - problems.start.to(_F64), dim=-1)
    ratio = outcome["joint_length"][ok] / line[ok]
    ms = 1e3 * seconds
    return {
        "n": n,
        "n_hard": int(hard.sum()),
        "success": _rate(ok),
        "success_hard": _rate(ok[hard]),
        "success_by_family": by_family,
        "planned": _rate(outcome["planned"]),
        "collision_free": _rate(outcome["collision_free"]),
        "goal_reached": _rate(outcome["goal_reached"]),
        "within_limits": _rate(outcome["within_limits"]),
        "latency_ms": {
            "p50": float(ms.median()),
            "p99": float(torch.quantile(ms, 0.99)),
            "mean": float(ms.mean()),
            "max": float(ms.max()),
        },
        "latency_hard_ms": {"p50": float(ms[hard].median())} if bool(hard.any()) else {"p50": None},
        "joint_length_ratio": float(ratio.median()) if ratio.numel() else None,
    }


def _pct(x: float | None) -> str:
    return "—" if x is None else f"{100 * x:.1f}"


def format_table(summaries: Mapping[str, Mapping]) -> str:
    """A Markdown table of :func:`summarize_outcome` rows, one per method (in the mapping's order)."""
    if not summaries:
        raise ConfigError("format_table needs at least one method's summary")
    families = [f for f in FAMILIES if any(f in s["success_by_family"] for s in summaries.values())]
    cols = [
        "method",
        "success (%)",
        "success, hard (%)",
        *[f"{f} (%)" for f in families],
        "collision-free (%)",
        "goal reached (%)",
        "p50 (ms)",
        "p99 (ms)",
        "joint length / line",
    ]
    rows = ["| " + " | ".join(cols) + " |", "|" + "|".join(["---"] + ["---:"] * (len(cols) - 1)) + "|"]
    for name, s in summaries.items():
        ratio = s["joint_length_ratio"]
        cells = [
            name,
            _pct(s["success"]),
            _pct(s["success_hard"]),
            *[_pct(s["success_by_family"].get(f)) for f in families],
            _pct(s["collision_free"]),
            _pct(s["goal_reached"]),
            _fmt_ms(s["latency_ms"]["p50"]),
            _fmt_ms(s["latency_ms"]["p99"]),
            "—" if ratio is None else f"{ratio:.2f}",
        ]
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


def _fmt_ms(x: float) -> str:
    return f"{x:.3g}" if x < 100 else f"{x:.0f}"


# --------------------------------------------------------------------------------------------------
# Figures (matplotlib, object-oriented API, Agg canvas, written atomically)
# --------------------------------------------------------------------------------------------------


def _figure_class():
    from .plots import _figure_class as figure_class

    return figure_class()


def _save(fig, path: str | Path, dpi: int) -> Path:
    return atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=dpi))


def _common_prefix(names: Sequence[str]) -> str:
    """The longest text all ``names`` start with (character by character)."""
    first = min(names, key=len)
    for k, ch in enumerate(first):
        if any(n[k] != ch for n in names):
            return first[:k]
    return first


def plot_success_latency(
    summaries: Mapping[str, Mapping],
    path: str | Path,
    curves: Mapping[str, Sequence[str]] | None = None,
    dpi: int = 120,
) -> Path:
    """Success (%) against median latency (ms, log scale): all problems and the hard ones, two panels.

    ``curves`` names groups of rows drawn as one line through their points (e.g. the optimiser at
    several step counts: ``{"optimiser": ["optimiser 25", "optimiser 100", ...]}``); every other row
    is a single point. Returns the path written.
    """
    Figure = _figure_class()
    if not summaries:
        raise ConfigError("plot_success_latency needs at least one method's summary")
    curves = dict(curves or {})
    for label, names in curves.items():
        missing = [m for m in names if m not in summaries]
        if missing:
            raise ConfigError(f"curve {label!r} names rows that are not in the summaries: {missing}")
    in_curve = {m for names in curves.values() for m in names}
    fig = Figure(figsize=(10, 4.2))
    axes = fig.subplots(1, 2, sharey=True)
    panels = (("success", "latency_ms", "all problems"), ("success_hard", "latency_hard_ms", "hard problems"))
    markers = "osD^vP*Xh<>"
    for ax, (key, lat, title) in zip(axes, panels, strict=True):
        k = 0
        for label, names in curves.items():
            pts = [(m, summaries[m][lat]["p50"], summaries[m][key]) for m in names]
            pts = [(m, x, 100 * y) for m, x, y in pts if x is not None and y is not None]
            if pts:
                ax.plot([x for _, x, _ in pts], [y for _, _, y in pts], "-o", color=f"C{k % 10}", label=label)
                common = _common_prefix(names) if len(names) > 1 else ""
                for m, x, y in pts:  # each point named by what differs between the curve's rows
                    text = m[len(common) :] or m
                    ax.annotate(text, (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7)
            k += 1
        for n, (name, s) in enumerate((m, s) for m, s in summaries.items() if m not in in_curve):
            x, y = s[lat]["p50"], s[key]
            if x is None or y is None:
                continue
            ax.plot([x], [100 * y], markers[n % len(markers)], color=f"C{k % 10}", ms=8, label=name)
            k += 1
        ax.set_xscale("log")
        ax.set_xlabel("median latency per problem (ms, log scale)")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("success (%)")
    axes[0].set_ylim(-2, 102)
    axes[1].legend(loc="best", fontsize=7)
    fig.tight_layout()
    return _save(fig, path, dpi)


def _draw_scene(ax, scene: Scene) -> list[np.ndarray]:
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    pts = []
    tables = {kind.kind: rows.detach().cpu().double().numpy() for kind, rows, _ in scene.tables(live=True)}
    faces = [f for b in tables["box"] for f in box_faces(b)]
    faces += [f for c in tables["cylinder"] for f in cylinder_faces(c)]
    if faces:
        ax.add_collection3d(
            Poly3DCollection(faces, facecolor="tan", edgecolor="0.35", linewidths=0.3, alpha=0.25)
        )
        pts += [corner for f in faces for corner in f]
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 16), np.linspace(0, np.pi, 9))
    for x, y, z, r in tables["sphere"]:
        ax.plot_surface(
            x + r * np.cos(u) * np.sin(v),
            y + r * np.sin(u) * np.sin(v),
            z + r * np.cos(v),
            color="tan",
            alpha=0.35,
            linewidth=0,
        )
        pts += [np.array([x, y, z]) - r, np.array([x, y, z]) + r]
    return pts


def plot_obstacle_plans(
    problems: ProblemSet,
    indices: Sequence[int],
    paths: Mapping[str, Sequence[torch.Tensor | None]],
    body: BodySpheres,
    path: str | Path,
    success: Mapping[str, Sequence[bool]] | None = None,
    titles: Sequence[str] | None = None,
    dpi: int = 120,
) -> Path:
    """3-D panels of a few problems, one per index: the boxes and spheres of its scene, the arm at the
    start and goal (grey polylines through the joint origins) and each method's executed end-effector
    path (sampled every 0.01 rad of joint motion).

    ``paths[method][j]``: that method's joint path ``(K, dof)`` for problem ``indices[j]`` (``None``:
    no path, only named in the legend). ``success[method][j]`` (optional) marks failed paths dashed. ``titles``: one per
    panel (default: the index, family and whether the problem is hard). Returns the path written.
    """
    Figure = _figure_class()
    indices = [int(i) for i in indices]
    if not indices:
        raise ConfigError("plot_obstacle_plans needs at least one problem index")
    if titles is not None and len(titles) != len(indices):
        raise ConfigError(f"titles must give one title per problem ({len(indices)}), got {len(titles)}")
    for name, ps in paths.items():
        if len(ps) != len(indices):
            raise ShapeError(f"method {name!r} has {len(ps)} paths for {len(indices)} problems")
    robot = body.robot
    kin = kinematics(robot, "fast")
    fig = Figure(figsize=(5.2 * len(indices), 5.4))
    for j, i in enumerate(indices):
        ax = fig.add_subplot(1, len(indices), j + 1, projection="3d")
        start, goal, scene = problems.problem(i)
        pts = _draw_scene(ax, scene)
        arm = kin.link_positions(torch.stack((start, goal)).to(_F64)).numpy()
        for a, style, label in ((arm[0], "-", "arm at start"), (arm[1], ":", "arm at goal")):
            ax.plot(
                *a.T,
                style,
                color="0.4",
                lw=2.0,
                marker="o",
                ms=2.5,
                alpha=0.7,
                label=label if j == 0 else None,
            )
        pts += list(arm.reshape(-1, 3))
        for k, (name, ps) in enumerate(paths.items()):
            p = ps[j]
            if p is None:  # named in the legend, nothing to draw
                ax.plot([], [], ":", color=f"C{k % 10}", label=f"{name} (no path)")
                continue
            p = torch.as_tensor(p).detach().cpu().to(_F64)
            step = float((p[1:] - p[:-1]).abs().amax()) if p.shape[0] > 1 else 0.0
            m = max(1, math.ceil(step / 0.01))
            f = torch.arange(m, dtype=_F64)[:, None] / m
            dense = torch.cat(
                ((p[:-1, None] + f * (p[1:, None] - p[:-1, None])).reshape(-1, p.shape[1]), p[-1:])
            )
            ee = kin.position(dense, validate=False).numpy()
            failed = success is not None and not bool(success[name][j])
            ax.plot(
                *ee.T,
                "--" if failed else "-",
                color=f"C{k % 10}",
                lw=1.6,
                label=(name + (" (failed)" if failed else "")),
            )
            pts += list(ee)
        ee_sg = kin.position(torch.stack((start, goal)).to(_F64)).numpy()
        first = j == 0
        ax.scatter(
            *ee_sg[0],
            s=60,
            color="tab:green",
            edgecolors="k",
            depthshade=False,
            zorder=5,
            label="start end effector" if first else None,
        )
        ax.scatter(
            *ee_sg[1],
            s=120,
            marker="*",
            color="tab:red",
            edgecolors="k",
            depthshade=False,
            zorder=5,
            label="goal end effector" if first else None,
        )
        allp = np.asarray(pts)
        lo, hi = allp.min(0), allp.max(0)
        lo[2] = min(lo[2], 0.0)
        centre, half = (lo + hi) / 2, float((hi - lo).max()) / 2 * 1.02 + 1e-3
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        ax.set_zlim(max(centre[2] - half, 0.0), max(centre[2] - half, 0.0) + 2 * half)
        ax.set_box_aspect((1, 1, 1))
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_zlabel("z (m)")
        ax.view_init(elev=25, azim=-60)
        fam = FAMILIES[int(problems.family[i])]
        title = f"problem {i} ({fam}{', hard' if bool(problems.hard[i]) else ''})"
        ax.set_title(title if titles is None else titles[j], fontsize=9)
        ax.legend(loc="upper left", fontsize=6, framealpha=0.8)
    fig.tight_layout()
    return _save(fig, path, dpi)
