"""Planning to a position when the robot's model is wrong.

A model-based planner trusts its URDF. Here the *true* robot is the bundled one (what motor babbling
runs on and what judges every plan) and the *believed* robot is a perturbed copy of its URDF
(:mod:`kinlearn.body.perturb`: link lengths scaled, joint zeros shifted), the model a user who
measured the arm imperfectly would hand to a planner.

The comparison (:func:`evaluate_believed`, :func:`model_error_sweep`) sends every planner to the same
held-out end-effector position goals, :func:`kinlearn.evaluation.workspace.heldout_pairs`, and judges the last
configuration of each executed joint path with the **true** robot's forward kinematics
(:func:`true_goal_error`): kinlearn's planner, learned from the true robot's babbling, never sees the
believed model; the model-based baselines (Cartesian line + DLS IK, joint interpolation and
RRT-Connect to a DLS IK solution, :func:`kinlearn.body.ik.position_ik`) get only the believed one.

The believed models and the IK (defined in :mod:`kinlearn.body`) are importable from here too.
"""

from __future__ import annotations

import hashlib
import time
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import torch

from ..body.ik import position_ik
from ..body.kinematics import kinematics
from ..body.perturb import (
    ModelError,
    believed_robot,
    check_amount,
    check_seed,
    draw_model_error,
    perturb_urdf,
    write_perturbed_urdf,
)
from ..body.robot import Robot, load_robot
from ..checks import check_last_dim
from ..data.problem import Problem
from ..errors import ConfigError, MissingDependencyError
from ..io import atomic_write
from ..planning import registry

__all__ = [
    "DEFAULT_LEVELS",
    "PLANNERS",
    "ModelError",
    "believed_robot",
    "draw_model_error",
    "evaluate_believed",
    "model_error_sweep",
    "model_error_table",
    "perturb_urdf",
    "plot_model_error",
    "position_ik",
    "true_goal_error",
    "write_perturbed_urdf",
]

#: The sweep's model-error levels: (link length error as a fraction, joint zero offset in degrees).
DEFAULT_LEVELS: tuple[tuple[float, float], ...] = (
    (0.0, 0.0),
    (0.01, 0.5),
    (0.02, 1.0),
    (0.03, 1.5),
    (0.05, 2.0),
    (0.10, 5.0),
)


def planner_labels() -> dict[str, str]:
    """Planners of the comparison, in table order: key → label. The first two are kinlearn's (they never
    see the believed model), the others are given the believed model: the calibrated IK, then every
    free-space baseline of the registry (:func:`kinlearn.baselines.names`), by its registry name; one
    that takes state goals only goes to the goal joints of DLS IK on the believed model."""
    labels = {
        "kinlearn": "kinlearn planner (learned from babbling)",
        "kinlearn_ik": "kinlearn goal joints (learned models alone)",
        "calibrated_ik": "DLS IK on the believed URDF calibrated from the same babbling",
    }
    for name in registry.names(avoids_obstacles=False):
        cls = registry.get(name)
        labels[name] = f"{cls.label}{'' if 'position' in cls.goals else ' to DLS IK'} (believed model)"
    return labels


#: :func:`planner_labels` of the built-in baselines.
PLANNERS: dict[str, str] = planner_labels()
_LEARNED = ("kinlearn", "kinlearn_ik")

#: A goal counts as reached when the true end effector ends within this distance of it (m).
SUCCESS_RADIUS = 0.01


# --------------------------------------------------------------------------------------------------
# Judging and the model-based baselines
# --------------------------------------------------------------------------------------------------


def true_goal_error(true_robot: Robot, joints: torch.Tensor, goal_positions: torch.Tensor) -> torch.Tensor:
    """How far the **true** end effector ends from each goal: ``‖FK_true(joints[..., -1, :]) − p‖`` (m).

    ``joints (..., T+1, dof)``: executed joint paths; ``goal_positions (..., 3)``. Returns ``(...)``.
    """
    check_last_dim(joints, true_robot.dof, "joint paths")
    check_last_dim(goal_positions, 3, "goal positions")
    last = joints[..., -1, :]
    p = kinematics(true_robot).position(last)
    return torch.linalg.vector_norm(p - goal_positions.to(p.dtype), dim=-1)


def evaluate_believed(
    true_robot: Robot,
    believed: Robot,
    start_joints: torch.Tensor,
    goal_positions: torch.Tensor,
    *,
    seed: int = 0,
    rrt: bool = True,
) -> dict[str, dict[str, torch.Tensor]]:
    """Run the model-based planners with the ``believed`` robot and judge them with the true one.

    ``start_joints (N, dof)``, ``goal_positions (N, 3)`` (float64 advised). The planners are the
    registry's free-space baselines (:func:`kinlearn.baselines.names`; the searches, RRT-Connect, only
    with ``rrt`` and their optional dependency installed), given the problems on the believed robot:
    the goal position where a baseline takes position goals, else the goal joints of DLS IK on the
    believed model. Returns, per baseline's registry name (:func:`planner_labels`): ``error``, the true
    goal error ``(N,)`` (m), and ``believed_error``, what the planner's own model says ``(N,)``.
    """
    if believed.dof != true_robot.dof or believed.joint_names != true_robot.joint_names:
        raise ConfigError(
            f"the believed robot's joints {believed.joint_names} differ from the true robot's {true_robot.joint_names}"
        )
    check_last_dim(start_joints, true_robot.dof, "start joints")
    check_last_dim(goal_positions, 3, "goal positions")
    q0, p = start_joints, goal_positions.to(start_joints.dtype)
    kin_b = kinematics(believed)
    q_ik = position_ik(believed, q0, p, seed=seed)
    to_position = Problem.make(believed, q0, goal_position=p)
    to_joints = Problem.make(believed, q0, q_ik)
    plans = {}
    for name in registry.names(avoids_obstacles=False):
        cls = registry.get(name)
        if cls.one_at_a_time and not rrt:
            continue
        problem = to_position if "position" in cls.goals else to_joints
        try:
            plans[name] = registry.make(name, believed, seed=seed).plan(problem)
        except MissingDependencyError:
            pass
    out = {}
    for key, plan in plans.items():
        last = plan.joints[..., -1, :]
        believed_error = torch.linalg.vector_norm(kin_b.position(last) - p, dim=-1)
        out[key] = {"error": true_goal_error(true_robot, plan.joints, p), "believed_error": believed_error}
    return out


def _calibration_data(true_robot: Robot, n: int):
    """``n`` babbled states of the true robot, the end effector observed with 1 mm Gaussian noise."""
    from ..data.babbling import BabblingConfig, babble

    walkers = min(1000, n)
    cfg = BabblingConfig(
        robot=true_robot.name,
        walkers=walkers,
        steps=-(-n // walkers),
        seed=4242,
        dtype="float64",
        ef_noise=1e-3,
    )
    return babble(cfg, robot=true_robot)


def _calibrated(true_robot: Robot, believed: Robot, q0: torch.Tensor, p: torch.Tensor, data) -> dict:
    """The believed URDF calibrated from ``data`` (the true robot's noisy babbling), then DLS IK on it."""
    from ..training.identify import identify

    result = identify(data, robot=believed)
    calibrated = Robot(f"{believed.name}-calibrated", result.urdf().encode(), result.ee_frame)
    q = position_ik(calibrated, q0, p)
    kin_c = kinematics(calibrated)
    return {
        "error": true_goal_error(true_robot, q[:, None], p),
        "believed_error": torch.linalg.vector_norm(kin_c.position(q) - p, dim=-1),
    }


# --------------------------------------------------------------------------------------------------
# The sweep
# --------------------------------------------------------------------------------------------------


def _summary(errors: torch.Tensor) -> dict[str, float]:
    e = errors.double()
    return {
        "median": float(e.median()),
        "p95": float(e.quantile(0.95)),
        "mean": float(e.mean()),
        "success": float((e <= SUCCESS_RADIUS).double().mean()),
    }


def _check_levels(levels) -> tuple[tuple[float, float], ...]:
    try:
        out = tuple((float(le), float(ae)) for le, ae in levels)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"levels must be pairs (length_error, angle_error_deg), got {levels!r}") from exc
    if not out:
        raise ConfigError("levels must hold at least one (length_error, angle_error_deg) pair")
    for le, ae in out:
        check_amount(le, "length_error", 1.0, "(a fraction of each length)")
        check_amount(ae, "angle_error_deg", 180.0, "degrees")
    return out


def model_error_sweep(
    robot: str = "iiwa14",
    levels: Sequence[tuple[float, float]] = DEFAULT_LEVELS,
    n_goals: int = 1000,
    seeds: Sequence[int] = (0, 1, 2),
    *,
    range_fraction: float = 0.9,
    planner=None,
    rrt: bool = True,
    calibrate: bool = True,
    calibration_samples: int = 20_000,
    progress: bool = False,
) -> dict:
    """Goal error of every planner against the size of the model error (a JSON-able dict).

    The goals are the end-effector positions of :func:`~kinlearn.evaluation.workspace.heldout_pairs` (``n_goals``,
    joints uniform within ``range_fraction`` of the limits, fixed seed), each planned from its pair's
    start joints. kinlearn's planner (``planner``, default ``Planner.default(robot)``) runs once: it
    does not depend on the believed model, so its result is the same at every level. For each level
    ``(length_error, angle_error_deg)`` and each perturbation seed, the model-based planners get that
    believed robot; results are pooled over the seeds (``median``/``p95``/``mean`` in metres,
    ``success``: share within 1 cm), with each seed's own numbers under ``per_seed``.

    ``calibrate``: the strongest model-based answer too — each believed URDF calibrated
    (:func:`~kinlearn.training.identify.identify`, the believed URDF as prior) from
    ``calibration_samples`` babbled states of the true robot observed with 1 mm noise, the same
    kind of data kinlearn learns from, then DLS IK on the calibrated chain (``calibrated_ik``).
    """
    from ..planning.planner import Planner
    from .workspace import heldout_pairs

    levels = _check_levels(levels)
    if isinstance(n_goals, bool) or not isinstance(n_goals, int) or n_goals < 1:
        raise ConfigError(f"n_goals must be an integer >= 1, got {n_goals!r}")
    seeds = tuple(check_seed(s) for s in seeds)
    if not seeds:
        raise ConfigError("seeds must hold at least one perturbation seed")
    true_robot = load_robot(robot)
    if planner is None:
        planner = Planner.default(robot)
    pairs = heldout_pairs(true_robot, n_goals, range_fraction=range_fraction)
    dof = true_robot.dof
    q0, p = pairs.start[:, :dof].double(), pairs.goal[:, dof:].double()

    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        plan = planner.plan(q0, goal_position=p)
    learned_seconds = time.perf_counter() - t0
    learned = {
        "kinlearn": true_goal_error(true_robot, plan.joints.double(), p),
        "kinlearn_ik": true_goal_error(true_robot, plan.goal[:, None, :dof].double(), p),
    }

    from tqdm.auto import tqdm

    cache: dict[str, dict[str, dict[str, torch.Tensor]]] = {}
    calib_data = _calibration_data(true_robot, calibration_samples) if calibrate else None
    jobs = [(lv, s) for lv in levels for s in seeds]
    results_levels = []
    runs_of: dict[tuple[float, float], list[tuple[int, dict]]] = {lv: [] for lv in levels}
    t1 = time.perf_counter()
    for (le, ae), seed in tqdm(jobs, desc="model-error sweep", disable=not progress):
        believed = believed_robot(true_robot, length_error=le, angle_error_deg=ae, seed=seed)
        digest = hashlib.sha256(believed.urdf).hexdigest()
        if digest not in cache:  # zero error: every seed gives the same model
            cache[digest] = evaluate_believed(true_robot, believed, q0, p, seed=seed, rrt=rrt)
            if calibrate:
                cache[digest]["calibrated_ik"] = _calibrated(true_robot, believed, q0, p, calib_data)
        runs_of[(le, ae)].append((seed, cache[digest]))
    baseline_seconds = time.perf_counter() - t1

    for le, ae in levels:
        runs = runs_of[(le, ae)]
        planners: dict[str, dict] = {}
        for key in planner_labels():
            if key in _LEARNED:
                planners[key] = {**_summary(learned[key]), "per_seed": None, "same_at_every_level": True}
                continue
            if key not in runs[0][1]:
                continue
            pooled = torch.cat([r[key]["error"] for _, r in runs])
            believed_pooled = torch.cat([r[key]["believed_error"] for _, r in runs])
            planners[key] = {
                **_summary(pooled),
                "believed_median": float(believed_pooled.median()),
                "believed_success": float((believed_pooled <= SUCCESS_RADIUS).double().mean()),
                "per_seed": {str(s): _summary(r[key]["error"]) for s, r in runs},
                "same_at_every_level": False,
            }
        results_levels.append({"length_error": le, "angle_error_deg": ae, "planners": planners})

    return {
        "robot": robot,
        "n_goals": n_goals,
        "range_fraction": range_fraction,
        "heldout_seed": pairs.config.seed,
        "seeds": list(seeds),
        "success_radius_m": SUCCESS_RADIUS,
        "planner_labels": {k: v for k, v in planner_labels().items() if k in results_levels[0]["planners"]},
        "kinlearn_tm": type(planner.tm).__name__,
        "kinlearn_domain_warnings": [str(w.message) for w in caught],
        "levels": results_levels,
        "seconds": {"kinlearn": learned_seconds, "baselines": baseline_seconds},
    }


def _level_label(le: float, ae: float) -> str:
    return f"{le * 100:g}% / {ae:g}°"


def model_error_table(results: Mapping) -> str:
    """A markdown table of :func:`model_error_sweep` results: one row per model-error level and planner."""
    labels = results["planner_labels"]
    n, seeds = results["n_goals"], len(results["seeds"])
    rows = [
        "| model error (lengths / zeros) | planner | goal error median (mm) | p95 (mm) | ≤ 1 cm | "
        "its own model's median (mm) |",
        "|:--|:--|--:|--:|--:|--:|",
    ]
    for level in results["levels"]:
        for key, r in level["planners"].items():
            own = r.get("believed_median")
            name = labels[key] + (" †" if r["same_at_every_level"] else "")
            rows.append(
                f"| {_level_label(level['length_error'], level['angle_error_deg'])} | {name} | "
                f"{r['median'] * 1000:.2f} | {r['p95'] * 1000:.1f} | {r['success'] * 100:.1f}% | "
                + ("—" if own is None else f"{own * 1000:.3f}")
                + " |"
            )
    rows.append("")
    rows.append(
        f"{n} held-out position goals ({results['robot']}, start and goal joints uniform within "
        f"±{results['range_fraction'] * 100:g}% of the limits), every executed path judged by the true "
        f"robot's FK; model-based rows pool {seeds} perturbation seed(s) per level. † kinlearn's planner "
        "never sees the believed model: it runs once and the same result is shown at every level. "
        "Joint interpolation and RRT-Connect end at the same IK solution, so their goal errors coincide."
    )
    return "\n".join(rows)


def plot_model_error(results: Mapping, path: str | Path, dpi: int = 130) -> Path:
    """Goal error against model error, one line per planner: median (left, log scale, with the 1 cm
    line), p95 (middle) and the share within 1 cm (right). Written as a PNG atomically."""
    try:
        from matplotlib.figure import Figure
    except ImportError as exc:
        raise MissingDependencyError(
            "plot_model_error needs matplotlib, which is not installed: `pip install kinlearn[plots]`"
        ) from exc
    levels = results["levels"]
    x = np.arange(len(levels))
    ticks = [_level_label(lv["length_error"], lv["angle_error_deg"]) for lv in levels]
    floor = 1e-2  # mm: errors below it (an exact model's ~1e-13 mm) are drawn at it
    fig = Figure(figsize=(15, 5.2), layout="constrained")
    axes = fig.subplots(1, 3)
    styles = {"kinlearn": ("C0", "o", "-"), "kinlearn_ik": ("C0", "s", "--")}
    for i, (key, label) in enumerate(results["planner_labels"].items()):
        color, marker, ls = styles.get(key, (f"C{i + 1}", "^v<>"[i % 4], "-"))
        med = np.array([lv["planners"][key]["median"] * 1000 for lv in levels])
        p95 = np.array([lv["planners"][key]["p95"] * 1000 for lv in levels])
        succ = np.array([lv["planners"][key]["success"] * 100 for lv in levels])
        kw = {"color": color, "marker": marker, "ls": ls, "label": label}
        if key == "rrt-connect":  # coincides with joint interpolation: hollow markers show both
            kw.update(mfc="none", ms=11)
        axes[0].plot(x, np.maximum(med, floor), **kw)
        axes[1].plot(x, np.maximum(p95, floor), **kw)
        axes[2].plot(x, succ, **kw)
        seeds = [lv["planners"][key].get("per_seed") for lv in levels]
        if all(seeds):
            lo = [min(s["median"] for s in d.values()) * 1000 for d in seeds]
            hi = [max(s["median"] for s in d.values()) * 1000 for d in seeds]
            axes[0].fill_between(x, np.maximum(lo, floor), np.maximum(hi, floor), color=color, alpha=0.15)
    for ax, title in zip(
        axes[:2], ("goal error, median (band: seeds' range)", "goal error, p95"), strict=True
    ):
        ax.set_yscale("log")
        ax.axhline(10.0, color="k", ls=":", lw=1)
        ax.text(x[0], 11.5, "1 cm", fontsize=8)
        ax.set_ylabel("true end-effector error (mm)")
        ax.set_title(title)
    axes[2].set_ylim(-3, 103)
    axes[2].set_ylabel("goals within 1 cm (%)")
    axes[2].set_title("success (true robot)")
    for ax in axes:
        ax.set_xticks(x, ticks)
        ax.set_xlabel("model error: link lengths / joint zeros (±, uniform)")
        ax.grid(alpha=0.3)
    handles, names = axes[0].get_legend_handles_labels()
    fig.legend(handles, names, loc="outside lower center", ncol=3, fontsize=8)
    fig.suptitle(
        f"Planning to {results['n_goals']} held-out positions when the model is wrong ({results['robot']}); "
        f"errors below {floor:g} mm drawn at {floor:g} mm",
        fontsize=10,
    )
    return atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=dpi))
