"""Figures like the paper's Fig. 3 (trajectories in 3-D with the arm) and Fig. 4 (metric histograms).

Plots only draw: the numbers come from :mod:`kinlearn.evaluation.metrics` and the arm's shape from
:meth:`FastKinematics.link_positions <kinlearn.body.kinematics.FastKinematics.link_positions>`.
matplotlib (``pip install kinlearn[plots]``) is imported when a figure is drawn, not with kinlearn,
and only through its object-oriented API with the Agg canvas: no pyplot, no global backend change.
Every figure is written as a PNG atomically (a crash never leaves a half-written file).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import torch

from ..body.kinematics import kinematics
from ..body.robot import Robot
from ..body.state import StateLayout
from ..errors import ConfigError, MissingDependencyError, ShapeError
from ..io import atomic_write
from ..planning.plan import Plan
from .metrics import METRICS, plan_metrics

__all__ = [
    "HISTOGRAM_GRID",
    "plot_good_bad",
    "plot_histograms",
    "plot_trajectories",
    "select_examples",
]

#: The histograms of :func:`plot_histograms`, row by row, laid out as in the paper's Fig. 4: distances
#: to the endpoints in the first column, spacing in the second, angles in the third.
HISTOGRAM_GRID: tuple[tuple[str, ...], ...] = (
    ("init_distance", "avg_spacing", "mean_angle"),
    ("final_distance", "max_spacing_deviation", "min_angle"),
)

#: Metrics for which a *lower* value is the worse trajectory (for :func:`select_examples`).
_LOWER_IS_WORSE = frozenset(
    {"mean_angle", "min_angle", "executed_mean_angle", "executed_min_angle", "success"}
)


def _figure_class():
    try:
        import mpl_toolkits.mplot3d  # noqa: F401  (registers the "3d" projection)
        from matplotlib.figure import Figure
    except ImportError as exc:
        raise MissingDependencyError(
            "kinlearn's figures need matplotlib, which is not installed: "
            "`pip install matplotlib` (or `pip install kinlearn[plots]`)"
        ) from exc
    return Figure


def _save(fig, path: str | Path, dpi: int) -> Path:
    return atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=dpi))


def _flat(plan: Plan) -> Plan:
    """The plan with its batch dimensions flattened to one, ``(N, ...)``."""
    if not isinstance(plan, Plan):
        raise ShapeError(f"plan must be a kinlearn.Plan, got {type(plan).__name__}")
    if plan.goal.ndim < 2:
        raise ShapeError(f"plots need a batch of plans, plan.goal (N, dof+3); got {tuple(plan.goal.shape)}")
    lead = plan.goal.ndim - 1

    def flat(x: torch.Tensor) -> torch.Tensor:
        x = x.detach().reshape(-1, *x.shape[lead:]).cpu()
        return x.double() if x.is_floating_point() else x

    return dataclasses.replace(
        plan, **{f: flat(getattr(plan, f)) for f in Plan._BATCHED if getattr(plan, f) is not None}
    )


def _check_indices(indices: Sequence[int], n: int) -> list[int]:
    out = [int(i) for i in indices]
    if not out:
        raise ConfigError("indices must name at least one trajectory")
    bad = [i for i in out if not -n <= i < n]
    if bad:
        raise ConfigError(f"trajectory indices {bad} are out of range for a batch of {n}")
    return [i % n for i in out]


def _draw(ax, plan: Plan, robot: Robot, indices: list[int], legend: bool = True) -> None:
    """Draw trajectories ``indices`` of a flat plan into a 3-D axes."""
    layout = StateLayout(robot.dof)
    fast = kinematics(robot, "fast")
    colors = [f"C{k % 10}" for k in range(len(indices))]
    everything = []
    for n, (i, color) in enumerate(zip(indices, colors, strict=True)):
        first = legend and n == 0
        _, ef0 = layout.split(plan.start[i])
        _, efT = layout.split(plan.goal[i])
        arm = fast.link_positions(torch.stack((plan.joints[i, 0], plan.joints[i, -1]))).numpy()
        for pts, style, label in ((arm[0], "-", "arm at start"), (arm[1], ":", "arm at end of plan")):
            ax.plot(
                *pts.T,
                style,
                color="0.45",
                lw=2.0,
                alpha=0.6,
                marker="o",
                ms=2.5,
                label=label if first else None,
            )
        planned = torch.cat((ef0[None], plan.waypoints[i], efT[None])).numpy()
        ax.plot(
            *planned.T,
            "--",
            color=color,
            lw=1.0,
            marker="o",
            ms=3.5,
            label="waypoints ŝ(1)…ŝ(T−1)" if first else None,
        )
        ax.plot(
            *plan.ef[i].numpy().T,
            "-",
            color=color,
            lw=1.8,
            alpha=0.8,
            label="executed end-effector path" if first else None,
        )
        ax.scatter(
            *ef0.numpy(),
            s=70,
            marker="o",
            color="tab:green",
            edgecolors="k",
            zorder=5,
            depthshade=False,
            label="start ef(s(0))" if first else None,
        )
        ax.scatter(
            *efT.numpy(),
            s=140,
            marker="*",
            color="tab:red",
            edgecolors="k",
            zorder=5,
            depthshade=False,
            label="goal ef(s(T))" if first else None,
        )
        everything += [arm.reshape(-1, 3), planned, plan.ef[i].numpy()]
    pts = np.concatenate(everything)
    center = (pts.max(0) + pts.min(0)) / 2
    half = float((pts.max(0) - pts.min(0)).max()) / 2 * 1.05 + 1e-3
    ax.set_xlim(float(center[0]) - half, float(center[0]) + half)
    ax.set_ylim(float(center[1]) - half, float(center[1]) + half)
    ax.set_zlim(float(center[2]) - half, float(center[2]) + half)
    ax.set_box_aspect((1, 1, 1))
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.view_init(elev=22, azim=-55)
    if legend:
        ax.legend(loc="upper left", fontsize=7, framealpha=0.8)


def plot_trajectories(
    plan: Plan,
    robot: Robot,
    indices: Sequence[int] | None,
    path: str | Path,
    title: str | None = None,
    dpi: int = 120,
) -> Path:
    """Draw selected trajectories of a batch of plans in 3-D and save a PNG (like the paper's Fig. 3).

    For each trajectory: the start (green circle) and goal (red star) end-effector positions, the
    planned waypoints joined to them (dashed, one colour per trajectory), the executed end-effector
    path ``plan.ef`` (solid), and the arm as a polyline through its joint origins at the plan's first
    and last configurations (grey, solid and dotted). ``indices=None`` draws the first five.
    Returns the path written.
    """
    Figure = _figure_class()
    plan = _flat(plan)
    n = plan.start.shape[0]
    indices = list(range(min(5, n))) if indices is None else _check_indices(indices, n)
    fig = Figure(figsize=(7, 6.5))
    ax = fig.add_subplot(projection="3d")
    _draw(ax, plan, robot, indices)
    if title:
        ax.set_title(title)
    fig.tight_layout()
    return _save(fig, path, dpi)


def select_examples(
    per_traj: Mapping[str, torch.Tensor], k: int = 3, metric: str = "max_spacing_deviation"
) -> tuple[list[int], list[int]]:
    """Indices of the ``k`` best and the ``k`` worst trajectories by one per-trajectory metric.

    ``per_traj`` is what :func:`~kinlearn.evaluation.metrics.trajectory_metrics` or
    :func:`~kinlearn.evaluation.metrics.plan_metrics` returns. Higher is worse for distances, spacing deviation
    and errors; lower is worse for angles and success. Returns ``(good, bad)``, best and worst first.
    """
    if metric not in per_traj:
        raise ConfigError(f"unknown metric {metric!r}; choose one of {sorted(per_traj)}")
    value = per_traj[metric].detach().reshape(-1).double().cpu()
    if isinstance(k, bool) or not isinstance(k, int) or k < 1:
        raise ConfigError(f"k must be an integer >= 1, got {k!r}")
    badness = -value if metric in _LOWER_IS_WORSE else value
    k = min(k, value.numel())
    order = torch.argsort(badness, stable=True)
    return order[:k].tolist(), order.flip(0)[:k].tolist()


def plot_good_bad(
    plan: Plan,
    robot: Robot,
    path: str | Path,
    k: int = 3,
    metric: str = "max_spacing_deviation",
    title: str | None = None,
    dpi: int = 120,
) -> Path:
    """Two 3-D panels side by side, the ``k`` best and the ``k`` worst plans by ``metric``, like Fig. 3.

    The ranking uses :func:`~kinlearn.evaluation.metrics.plan_metrics` (the default ranks by maximum spacing
    deviation, the paper's "uneven spacing" of its right panel). Returns the path written.
    """
    Figure = _figure_class()
    flat = _flat(plan)
    good, bad = select_examples(plan_metrics(flat, robot), k=k, metric=metric)
    label = METRICS[metric].label if metric in METRICS else metric
    fig = Figure(figsize=(13, 6.5))
    for col, (indices, name) in enumerate(((good, "best"), (bad, "worst"))):
        ax = fig.add_subplot(1, 2, col + 1, projection="3d")
        _draw(ax, flat, robot, indices, legend=col == 0)
        ax.set_title(f"{len(indices)} {name} by {label}")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path, dpi)


def plot_histograms(
    per_traj_metrics: Mapping[str, torch.Tensor],
    path: str | Path,
    title: str | None = None,
    paper: Mapping[str, Mapping[str, float]] | None = None,
    bins: int = 50,
    dpi: int = 120,
) -> Path:
    """Histograms of the paper's six metrics with each mean as a dashed line (like the paper's Fig. 4).

    ``per_traj_metrics`` is what :func:`~kinlearn.evaluation.metrics.trajectory_metrics` or
    :func:`~kinlearn.evaluation.metrics.plan_metrics` returns; the panels follow :data:`HISTOGRAM_GRID`. With
    ``paper`` (e.g. ``metrics.PAPER_TABLE2[4]``) the paper's mean is marked too, dotted red, where it
    gives one. Returns the path written.
    """
    Figure = _figure_class()
    missing = [m for row in HISTOGRAM_GRID for m in row if m not in per_traj_metrics]
    if missing:
        raise ConfigError(f"plot_histograms needs the metrics {missing}; pass trajectory_metrics(...) output")
    rows, cols = len(HISTOGRAM_GRID), len(HISTOGRAM_GRID[0])
    fig = Figure(figsize=(4.2 * cols, 3.2 * rows))
    for r, row in enumerate(HISTOGRAM_GRID):
        for c, name in enumerate(row):
            ax = fig.add_subplot(rows, cols, r * cols + c + 1)
            x = per_traj_metrics[name].detach().reshape(-1).double().cpu().numpy()
            info = METRICS[name]
            ax.hist(x, bins=bins, color="tab:blue", alpha=0.75)
            mean = float(x.mean())
            ax.axvline(mean, color="k", ls="--", lw=1.5, label=f"mean {mean:.{info.decimals + 1}f}")
            reference = (paper or {}).get(name, {}).get("mean")
            if reference is not None:
                ax.axvline(reference, color="tab:red", ls=":", lw=1.5, label=f"paper {reference:g}")
            ax.set_xlabel(info.label)
            ax.set_ylabel("trajectories")
            ax.legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path, dpi)
