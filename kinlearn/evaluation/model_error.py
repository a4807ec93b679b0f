"""Planning to a position when the robot's model is wrong.

A model-based planner trusts its URDF. Here the *true* robot is the bundled one (what motor babbling
runs on and what judges every plan) and the *believed* robot is a perturbed copy of its URDF, the
model a user who measured the arm imperfectly would hand to a planner:

- every joint origin's translation (the link lengths) is scaled by ``1 + U(-e, e)``;
- every revolute (and continuous) joint's zero is shifted by ``U(-a, a)`` degrees. The shift is a
  rotation about the joint's axis folded into the joint's origin rpy, so the believed URDF is an
  ordinary URDF whose kinematics at ``q`` equal the true kinematics at ``q + offset`` (up to the
  length changes).

The comparison (:func:`evaluate_believed`, :func:`model_error_sweep`) sends every planner to the same
held-out end-effector position goals, :func:`kinlearn.evaluation.workspace.heldout_pairs`, and judges the last
configuration of each executed joint path with the **true** robot's forward kinematics
(:func:`true_goal_error`): kinlearn's planner, learned from the true robot's babbling, never sees the
believed model; the model-based baselines (Cartesian line + DLS IK, joint interpolation and
RRT-Connect to a DLS IK solution) get only the believed one.
"""

from __future__ import annotations

import hashlib
import math
import time
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ..body.kinematics import dls_step, kinematics
from ..body.robot import ROBOTS, Robot, load_robot
from ..checks import check_finite, check_last_dim
from ..errors import ConfigError, MissingDependencyError, RobotDescriptionError, UnknownRobotError
from ..io import atomic_write
from ..planning.baselines import cartesian_dls, joint_interpolation, rrt_connect

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

#: Planners of the comparison, in table order: key → label. The first two are kinlearn's (they never
#: see the believed model), the others are given the believed model.
PLANNERS: dict[str, str] = {
    "kinlearn": "kinlearn planner (learned from babbling)",
    "kinlearn_ik": "kinlearn goal joints (learned models alone)",
    "calibrated_ik": "DLS IK on the believed URDF calibrated from the same babbling",
    "cartesian_dls": "Cartesian line + DLS IK (believed model)",
    "joint_interpolation": "joint interpolation to DLS IK (believed model)",
    "rrt_connect": "RRT-Connect to DLS IK (believed model)",
}
_LEARNED = ("kinlearn", "kinlearn_ik")

#: A goal counts as reached when the true end effector ends within this distance of it (m).
SUCCESS_RADIUS = 0.01


# --------------------------------------------------------------------------------------------------
# The believed robot
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ModelError:
    """One drawn model error: per joint of the URDF (by name), the factor its origin's translation is
    scaled by and the shift of its zero (rad; 0 for joints that are not revolute or continuous).

    The believed kinematics at ``q`` equal the true ones at ``q + offset`` when every scale is 1.
    """

    robot: str
    length_error: float
    angle_error_deg: float
    seed: int
    length_scale: Mapping[str, float]
    zero_offset: Mapping[str, float]

    def offsets(self, robot: Robot) -> torch.Tensor:
        """The zero offsets of ``robot``'s movable joints, in its joint order ``(dof,)`` (float64, rad)."""
        return torch.tensor([self.zero_offset[n] for n in robot.joint_names], dtype=torch.float64)


def _check_amount(value: object, what: str, upper: float, unit: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ConfigError(f"{what} must be a number, got {type(value).__name__}")
    value = float(value)
    if not math.isfinite(value) or value < 0.0 or value >= upper:
        raise ConfigError(f"{what} must be a finite number in [0, {upper}) {unit}, got {value!r}")
    return value


def _check_seed(seed: object) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError(f"seed must be an integer >= 0, got {seed!r}")
    return int(seed)


def _source(robot_name_or_path: str | Path | Robot) -> tuple[str, bytes, str | None]:
    """The robot's name, URDF bytes and (for a named robot) end-effector frame."""
    if isinstance(robot_name_or_path, Robot):
        r = robot_name_or_path
        return r.name, r.urdf, r.ee_frame
    if not isinstance(robot_name_or_path, (str, Path)):
        raise ConfigError(
            f"robot must be a robot name, a URDF path or a kinlearn Robot, got {type(robot_name_or_path).__name__}"
        )
    text = str(robot_name_or_path)
    if text in ROBOTS:
        r = load_robot(text)
        return r.name, r.urdf, r.ee_frame
    path = Path(text)
    if path.is_file():
        return path.stem, path.read_bytes(), None
    raise UnknownRobotError(
        f"unknown robot {text!r}: give one of {', '.join(sorted(ROBOTS))} or the path of an existing .urdf file"
    )


def _parse(urdf: bytes, name: str) -> ET.Element:
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    try:
        return ET.fromstring(urdf, parser=parser)
    except ET.ParseError as exc:
        raise RobotDescriptionError(f"{name}: the URDF is not valid XML: {exc}") from exc


def _numbers(text: str | None, default: tuple[float, float, float], what: str) -> np.ndarray:
    if text is None:
        return np.array(default, dtype=np.float64)
    values = [float(v) for v in text.split()]
    if len(values) != 3:
        raise RobotDescriptionError(f"{what}: expected 3 numbers, got {text!r}")
    return np.array(values)


def _rpy_to_matrix(r: float, p: float, y: float) -> np.ndarray:
    """URDF fixed-axis roll-pitch-yaw: R = Rz(y) Ry(p) Rx(r)."""
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def _matrix_to_rpy(R: np.ndarray) -> tuple[float, float, float]:
    """Roll, pitch, yaw with ``_rpy_to_matrix(r, p, y) == R`` (pitch in [-π/2, π/2])."""
    cp = math.hypot(R[0, 0], R[1, 0])
    p = math.atan2(-R[2, 0], cp)
    if cp > 1e-9:
        return math.atan2(R[2, 1], R[2, 2]), p, math.atan2(R[1, 0], R[0, 0])
    # Gimbal lock (pitch ±π/2): only roll ∓ yaw is defined; take yaw = 0.
    return math.atan2(-R[1, 2], R[1, 1]), p, 0.0


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation by ``angle`` about the unit vector ``axis`` (Rodrigues)."""
    k = axis / np.linalg.norm(axis)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)


def _fmt(values) -> str:
    return " ".join(repr(float(v)) for v in values)


def _perturb(
    robot_name_or_path, length_error: float, angle_error_deg: float, seed: int, misalign_deg: float = 0.0
) -> tuple[ModelError, bytes]:
    e = _check_amount(length_error, "length_error", 1.0, "(a fraction of each length)")
    a = _check_amount(angle_error_deg, "angle_error_deg", 180.0, "degrees")
    m = _check_amount(misalign_deg, "misalign_deg", 180.0, "degrees")
    seed = _check_seed(seed)
    name, urdf, _ = _source(robot_name_or_path)
    root = _parse(urdf, name)
    rng = np.random.default_rng(seed)
    # Misalignment from a stream of its own: the other draws of a seed stay what they were.
    tilt_rng = np.random.default_rng([seed, 1])
    scales: dict[str, float] = {}
    offsets: dict[str, float] = {}
    for el in root.iter("joint"):
        if el.find("parent") is None or el.find("child") is None:  # not a kinematic joint (transmissions)
            continue
        jname = el.get("name")
        # Two draws for every joint, whatever its type: the same seed scales the same pattern at every
        # level, and adding error to one joint kind does not reshuffle the others.
        u_len, u_ang = rng.uniform(-1.0, 1.0, size=2)
        scale = 1.0 + e * float(u_len)
        offset = math.radians(a) * float(u_ang) if el.get("type") in ("revolute", "continuous") else 0.0
        scales[jname], offsets[jname] = scale, offset
        tilt_axis, tilt = tilt_rng.normal(size=3), math.radians(m) * float(tilt_rng.uniform(-1.0, 1.0))
        if scale == 1.0 and offset == 0.0 and tilt == 0.0:
            continue
        origin = el.find("origin")
        if origin is None:
            origin = ET.SubElement(el, "origin")
        what = f"{name}: joint {jname}"
        xyz = _numbers(origin.get("xyz"), (0.0, 0.0, 0.0), f"{what} origin xyz")
        rpy = _numbers(origin.get("rpy"), (0.0, 0.0, 0.0), f"{what} origin rpy")
        if scale != 1.0 and np.any(xyz != 0.0):
            origin.set("xyz", _fmt(xyz * scale))
        if tilt != 0.0:  # the origin's rotation tilted about a random axis: misaligned joint axes
            rpy = np.array(_matrix_to_rpy(_rpy_to_matrix(*rpy) @ _axis_rotation(tilt_axis, tilt)))
            origin.set("rpy", _fmt(rpy))
        if offset != 0.0:
            axis_el = el.find("axis")
            axis = _numbers(None if axis_el is None else axis_el.get("xyz"), (1.0, 0.0, 0.0), f"{what} axis")
            if not np.linalg.norm(axis) > 0.0:
                raise RobotDescriptionError(f"{what} has a zero axis")
            R = _rpy_to_matrix(*rpy) @ _axis_rotation(axis, offset)
            origin.set("rpy", _fmt(_matrix_to_rpy(R)))
    out = ET.tostring(root, encoding="utf-8", xml_declaration=True)
    return ModelError(name, e, a, seed, scales, offsets), out


def draw_model_error(
    robot_name_or_path: str | Path | Robot,
    *,
    length_error: float = 0.02,
    angle_error_deg: float = 1.0,
    seed: int = 0,
) -> ModelError:
    """The model error :func:`perturb_urdf` applies for these arguments (same seed, same draw)."""
    return _perturb(robot_name_or_path, length_error, angle_error_deg, seed)[0]


def perturb_urdf(
    robot_name_or_path: str | Path | Robot,
    *,
    length_error: float = 0.02,
    angle_error_deg: float = 1.0,
    seed: int = 0,
    misalign_deg: float = 0.0,
) -> bytes:
    """A *believed* copy of a robot's URDF, as UTF-8 bytes: lengths off by up to ``length_error``
    (a fraction), joint zeros off by up to ``angle_error_deg`` degrees, drawn uniformly with ``seed``.

    ``robot_name_or_path``: a name of :data:`~kinlearn.body.robot.ROBOTS`, the path of a URDF file, or a
    :class:`~kinlearn.body.robot.Robot`. Each joint's origin translation is scaled by ``1 + U(-e, e)``; each
    revolute or continuous joint's origin rotation is followed by a rotation of ``U(-a, a)`` about the
    joint's axis (see :func:`draw_model_error` for the values drawn); with ``misalign_deg`` it is also
    tilted by up to that angle about a random axis (misaligned joint axes, drawn from a stream of its
    own). Names, limits, axes, links and everything else are kept; with every error 0 the joints are
    unchanged.

    Raises :class:`~kinlearn.errors.ConfigError` for an error outside [0, 1) (lengths) or [0, 180)
    (degrees), NaN, or a seed that is not an integer ≥ 0; :class:`~kinlearn.errors.UnknownRobotError`
    for a name that is no robot and no file.
    """
    return _perturb(robot_name_or_path, length_error, angle_error_deg, seed, misalign_deg)[1]


def write_perturbed_urdf(
    robot_name_or_path: str | Path | Robot,
    path: str | Path,
    *,
    length_error: float = 0.02,
    angle_error_deg: float = 1.0,
    seed: int = 0,
    misalign_deg: float = 0.0,
) -> Path:
    """Write :func:`perturb_urdf`'s believed URDF to ``path`` (atomically) and return the path.

    Load it with ``load_robot(path, ee_frame=ROBOTS[name].ee_frame)``. ``load_robot`` caches robots by
    path: write each believed model to its own file, or use :func:`believed_robot`.
    """
    data = perturb_urdf(
        robot_name_or_path,
        length_error=length_error,
        angle_error_deg=angle_error_deg,
        seed=seed,
        misalign_deg=misalign_deg,
    )
    return atomic_write(path, lambda tmp: tmp.write_bytes(data))


#: Believed robots by (URDF digest, ee frame). Kept alive for the process: kinematics are cached by the
#: robot object's identity, which must therefore never be reused by another robot.
_BELIEVED: dict[tuple[str, str], Robot] = {}


def believed_robot(
    robot_name_or_path: str | Path | Robot,
    *,
    length_error: float = 0.02,
    angle_error_deg: float = 1.0,
    seed: int = 0,
    ee_frame: str | None = None,
    misalign_deg: float = 0.0,
) -> Robot:
    """The believed robot of :func:`perturb_urdf`, parsed in memory (no file written).

    ``ee_frame`` defaults to the named robot's end effector; a URDF path needs it. Robots are cached by
    the believed URDF's content: the same arguments return the same object.
    """
    name, _, default_ee = _source(robot_name_or_path)
    ee = ee_frame or default_ee
    if ee is None:
        raise ConfigError(f"a believed model of {robot_name_or_path} needs ee_frame=<end-effector link>")
    data = perturb_urdf(
        robot_name_or_path,
        length_error=length_error,
        angle_error_deg=angle_error_deg,
        seed=seed,
        misalign_deg=misalign_deg,
    )
    key = (hashlib.sha256(data).hexdigest(), ee)
    if key not in _BELIEVED:
        _BELIEVED[key] = Robot(f"{name}-believed", data, ee)
    return _BELIEVED[key]


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


def position_ik(
    robot: Robot,
    start_joints: torch.Tensor,
    goal_positions: torch.Tensor,
    *,
    restarts: int = 8,
    tolerance: float = 1e-6,
    damping: float = 1e-2,
    seed: int = 0,
) -> torch.Tensor:
    """Joints ``(..., dof)`` that put ``robot``'s end effector on ``goal_positions (..., 3)``, by DLS IK.

    Damped least squares (:func:`~kinlearn.body.kinematics.dls_step`, clamped to the limits) from the start
    joints; goals not reached within ``tolerance`` metres are tried again by following the straight
    line from the start's end effector, then from up to ``restarts`` random configurations (drawn with
    ``seed``). Each goal keeps its best solution; one that ``robot`` cannot reach ends as close as the
    search came. ``robot`` is the model the IK trusts: pass the believed robot for a model-based
    planner.
    """
    check_last_dim(start_joints, robot.dof, "start joints")
    check_last_dim(goal_positions, 3, "goal positions")
    check_finite(start_joints, "start joints")
    check_finite(goal_positions, "goal positions")
    if isinstance(restarts, bool) or not isinstance(restarts, int) or restarts < 0:
        raise ConfigError(f"restarts must be an integer >= 0, got {restarts!r}")
    if not tolerance > 0.0 or not damping > 0.0:
        raise ConfigError(f"tolerance and damping must be > 0 (metres), got {tolerance!r} and {damping!r}")
    batch = start_joints.shape[:-1]
    q0 = start_joints.reshape(-1, robot.dof)
    p = goal_positions.to(q0.dtype).expand(*batch, 3).reshape(-1, 3)
    kin = kinematics(robot)

    def solve(q: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        for _ in range(10):  # converged goals stay put: DLS steps there are ~0
            q = dls_step(kin, q, target, iterations=10, damping=damping)
        return q

    def error(q: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        return torch.linalg.vector_norm(kin.position(q, validate=False) - target, dim=-1)

    best = solve(q0, p)
    err = error(best, p)
    todo = torch.nonzero(err > tolerance).flatten()
    if todo.numel():  # along the straight line, 20 steps
        q, e0 = q0[todo], kin.position(q0[todo], validate=False)
        for k in range(1, 21):
            q = dls_step(kin, q, e0 + (k / 20) * (p[todo] - e0), iterations=10, damping=damping)
        q = solve(q, p[todo])
        e = error(q, p[todo])
        better = e < err[todo]
        best[todo[better]], err[todo[better]] = q[better], e[better]
    gen = torch.Generator().manual_seed(seed)
    for _ in range(restarts):
        todo = torch.nonzero(err > tolerance).flatten()
        if not todo.numel():
            break
        q = solve(robot.sample(todo.numel(), gen, dtype=q0.dtype).to(q0.device), p[todo])
        e = error(q, p[todo])
        better = e < err[todo]
        best[todo[better]], err[todo[better]] = q[better], e[better]
    return best.reshape(*batch, robot.dof)


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

    ``start_joints (N, dof)``, ``goal_positions (N, 3)`` (float64 advised). The planners get start
    states built with the believed FK and the goal position as the goal's end effector. Returns, per
    planner key of :data:`PLANNERS` (``rrt_connect`` only with ``rrt`` and OMPL installed): ``error``,
    the true goal error ``(N,)`` (m), and ``believed_error``, what the planner's own model says ``(N,)``.
    """
    if believed.dof != true_robot.dof or believed.joint_names != true_robot.joint_names:
        raise ConfigError(
            f"the believed robot's joints {believed.joint_names} differ from the true robot's {true_robot.joint_names}"
        )
    check_last_dim(start_joints, true_robot.dof, "start joints")
    check_last_dim(goal_positions, 3, "goal positions")
    q0, p = start_joints, goal_positions.to(start_joints.dtype)
    kin_b = kinematics(believed)
    start = torch.cat((q0, kin_b.position(q0)), dim=-1)
    q_ik = position_ik(believed, q0, p, seed=seed)
    goal = torch.cat((q_ik, p), dim=-1)
    plans = {
        "cartesian_dls": cartesian_dls(believed, start, goal),
        "joint_interpolation": joint_interpolation(believed, start, goal),
    }
    if rrt:
        try:
            plans["rrt_connect"] = rrt_connect(believed, start, goal, seed=seed)
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
        _check_amount(le, "length_error", 1.0, "(a fraction of each length)")
        _check_amount(ae, "angle_error_deg", 180.0, "degrees")
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
    seeds = tuple(_check_seed(s) for s in seeds)
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
        for key in PLANNERS:
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
        "planner_labels": {k: v for k, v in PLANNERS.items() if k in results_levels[0]["planners"]},
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
        if key == "rrt_connect":  # coincides with joint interpolation: hollow markers show both
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
