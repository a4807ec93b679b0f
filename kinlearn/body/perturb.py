"""A *believed* copy of a robot's URDF: the model a user who measured the arm imperfectly would hand to a
planner.

- every joint origin's translation (the link lengths) is scaled by ``1 + U(-e, e)``;
- every revolute (and continuous) joint's zero is shifted by ``U(-a, a)`` degrees. The shift is a
  rotation about the joint's axis folded into the joint's origin rpy, so the believed URDF is an
  ordinary URDF whose kinematics at ``q`` equal the true kinematics at ``q + offset`` (up to the
  length changes);
- optionally (``misalign_deg``) every joint origin's rotation is tilted about a random axis.

:func:`perturb_urdf` gives the URDF's bytes, :func:`write_perturbed_urdf` a file, :func:`believed_robot` the
parsed robot and :func:`draw_model_error` the errors drawn. :mod:`kinlearn.evaluation.model_error`
plans with such models and judges the plans with the true robot.
"""

from __future__ import annotations

import hashlib
import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ..errors import ConfigError, RobotDescriptionError, UnknownRobotError
from ..io import atomic_write
from .robot import ROBOTS, Robot, load_robot
from .rotation import axis_rotation, matrix_rpy, rpy_matrix

__all__ = [
    "ModelError",
    "believed_robot",
    "draw_model_error",
    "perturb_urdf",
    "write_perturbed_urdf",
]


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


def check_amount(value: object, what: str, upper: float, unit: str) -> float:
    """``value`` as a float in [0, ``upper``); :class:`~kinlearn.errors.ConfigError` naming ``what`` otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ConfigError(f"{what} must be a number, got {type(value).__name__}")
    value = float(value)
    if not math.isfinite(value) or value < 0.0 or value >= upper:
        raise ConfigError(f"{what} must be a finite number in [0, {upper}) {unit}, got {value!r}")
    return value


def check_seed(seed: object) -> int:
    """``seed`` as an int ≥ 0; :class:`~kinlearn.errors.ConfigError` otherwise."""
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


def _fmt(values) -> str:
    return " ".join(repr(float(v)) for v in values)


def _perturb(
    robot_name_or_path, length_error: float, angle_error_deg: float, seed: int, misalign_deg: float = 0.0
) -> tuple[ModelError, bytes]:
    e = check_amount(length_error, "length_error", 1.0, "(a fraction of each length)")
    a = check_amount(angle_error_deg, "angle_error_deg", 180.0, "degrees")
    m = check_amount(misalign_deg, "misalign_deg", 180.0, "degrees")
    seed = check_seed(seed)
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
            rpy = np.array(matrix_rpy(rpy_matrix(*rpy) @ axis_rotation(tilt_axis, tilt)))
            origin.set("rpy", _fmt(rpy))
        if offset != 0.0:
            axis_el = el.find("axis")
            axis = _numbers(None if axis_el is None else axis_el.get("xyz"), (1.0, 0.0, 0.0), f"{what} axis")
            if not np.linalg.norm(axis) > 0.0:
                raise RobotDescriptionError(f"{what} has a zero axis")
            R = rpy_matrix(*rpy) @ axis_rotation(axis, offset)
            origin.set("rpy", _fmt(matrix_rpy(R)))
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
