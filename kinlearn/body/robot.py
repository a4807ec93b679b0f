"""Robots by name or URDF path, parsed once into an exact float64 serial chain.

The chain parsed here is the single description of a robot's geometry in kinlearn: the fast
position path, the pytorch-kinematics backend (whose own float32 parse is overwritten with these
values) and the joint limits all come from it. Pinocchio parses the same URDF independently, which
is what makes it a useful cross-check.
"""

from __future__ import annotations

import copy
import importlib.metadata
import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from numpy.typing import ArrayLike

from ..checks import check_finite, check_last_dim, check_region, real_array
from ..errors import (
    ConfigError,
    JointLimitError,
    RobotDescriptionError,
    UnknownRobotError,
)
from .rotation import rpy_matrix

__all__ = [
    "ROBOTS",
    "Joint",
    "Robot",
    "RobotSpec",
    "available_robots",
    "load_robot",
    "register_robot",
    "unregister_robot",
]


@dataclass(frozen=True)
class RobotSpec:
    """Where a named robot's URDF lives, which frame is its end effector, and optionally its home
    configuration (rad) and the paper-task goal region (m: x_min, x_max, y_min, y_max, z_min, z_max)."""

    source: str  # "bundled" (this package's robots/), "example-robot-data" or "file" (registered)
    relpath: str  # under the source's folder; for "file", the URDF's absolute path
    ee_frame: str
    description: str
    home: tuple[float, ...] | None = None
    region: tuple[float, ...] | None = None


ROBOTS: dict[str, RobotSpec] = {
    "iiwa14": RobotSpec("bundled", "iiwa14/iiwa14.urdf", "iiwa_link_ee", "KUKA LBR iiwa 14 R820, 7-DoF"),
    "panda": RobotSpec(
        "example-robot-data", "panda_description/urdf/panda.urdf", "panda_hand_tcp", "Franka Panda, 7-DoF"
    ),
    "ur5": RobotSpec("example-robot-data", "ur_description/urdf/ur5_robot.urdf", "tool0", "UR5, 6-DoF"),
    "xarm7": RobotSpec("example-robot-data", "xarm_description/urdf/xarm7.urdf", "link_eef", "xArm 7, 7-DoF"),
    "z1": RobotSpec(
        "example-robot-data", "z1_description/urdf/z1.urdf", "gripperStator", "Unitree Z1, 6-DoF"
    ),
}


#: The names kinlearn ships; :func:`register_robot` adds others, and cannot replace these.
BUILTIN_ROBOTS = frozenset(ROBOTS)


def _check_sphere_radii(urdf: bytes, path: Path) -> None:
    """A spherized URDF's ``<sphere radius>``: each a finite number of metres > 0, else
    :class:`RobotDescriptionError` naming the link (said at registration, not when the body is built)."""
    root = validate_urdf(urdf, f"the sphere URDF {path}")
    for link in root.iter("link"):
        for sphere in link.iterfind("collision/geometry/sphere"):
            text = sphere.get("radius")
            try:
                r = float(text if text is not None else "nan")
            except (TypeError, ValueError):
                r = math.nan
            if not (math.isfinite(r) and 0 < r < 1e3):
                raise RobotDescriptionError(
                    f"{path}: a collision sphere of link {link.get('name')!r} has radius {text!r}; a radius "
                    "is a finite number of metres > 0"
                )


def register_robot(
    name: str,
    urdf: str | Path,
    ee_frame: str,
    *,
    home: ArrayLike | None = None,
    region: ArrayLike | None = None,
    description: str = "",
    overwrite: bool = False,
    spheres: str | Path | None = None,
) -> Robot:
    """Make a robot from a URDF file known by ``name`` to every kinlearn function in this process.

    After this, ``name`` goes wherever a bundled arm's name goes: babbling, FM/IM, endpoint pairs, TM
    training, planners, checkpoints (which record it). ``home``: a configuration within the limits
    (the paper-task starts spread around it; default: the middle of the joint range). ``region``: the
    paper-task goal box (default: the iiwa14's, scaled by the arm's reach). The URDF is parsed now,
    so a bad file, frame, home or region fails here. Registration lives in this process only: worker
    processes (``kinlearn reproduce --workers``) must register it too. ``spheres``: a spherized URDF
    (one ``<collision><geometry><sphere>`` per sphere, the same joint names) giving the robot a collision
    body (:func:`kinlearn.collision.body_spheres`; spheres on fixed links are folded onto their moving
    parent). Returns the loaded robot.
    """
    if (
        not isinstance(name, str)
        or not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.+-]*", name)
        or name.lower().endswith(".urdf")
    ):
        raise ConfigError(
            f"a robot name must be a word of letters, digits and _ . + - (it names files and folders), not a "
            f"path; got {name!r}"
        )
    if name in BUILTIN_ROBOTS:
        raise ConfigError(f"{name!r} is one of kinlearn's own robots; register yours under another name")
    if name in ROBOTS and not overwrite:
        raise ConfigError(f"a robot named {name!r} is registered already (overwrite=True replaces it)")
    path = Path(urdf).resolve()
    if not path.is_file():
        raise UnknownRobotError(f"no URDF file at {path}")
    robot = Robot(name, path.read_bytes(), ee_frame, path)
    if spheres is not None:
        sphere_path = Path(spheres).resolve()
        if not sphere_path.is_file():
            raise UnknownRobotError(f"no sphere URDF file at {sphere_path}")
        if (
            sphere_path.suffix.lower() != ".json"
        ):  # a spherized URDF (a .json sphere model is checked where read)
            _check_sphere_radii(sphere_path.read_bytes(), sphere_path)
        robot.sphere_urdf = sphere_path
    if home is not None:
        h = real_array(home, "home").astype(float)
        if h.shape != (robot.dof,) or not np.isfinite(h).all():
            raise ConfigError(f"home must be {robot.dof} finite joint values, got {home!r}")
        if ((h < robot.lower) | (h > robot.upper)).any():
            raise JointLimitError(f"home {tuple(h)} leaves {name}'s joint limits")
        home = tuple(float(v) for v in h)
    if region is not None:
        region = check_region(region)
    unregister_robot(name)
    ROBOTS[name] = RobotSpec(
        "file", str(path), ee_frame, description or f"{path.name} ({robot.dof}-DoF)", home, region
    )
    _CACHE[(name, "")] = robot
    return robot


def unregister_robot(name: str) -> None:
    """Forget a robot :func:`register_robot` added (kinlearn's own cannot be removed)."""
    if name in BUILTIN_ROBOTS:
        raise ConfigError(f"{name!r} is one of kinlearn's own robots")
    ROBOTS.pop(name, None)
    for key in [k for k in _CACHE if k[0] == name]:
        del _CACHE[key]


def available_robots() -> list[str]:
    """Names accepted by :func:`load_robot`."""
    return sorted(ROBOTS)


def _bundled_dir() -> Path:
    here = Path(__file__).resolve().parents[1]  # the package folder
    for candidate in (here / "_robots", here.parent / "robots"):  # installed wheel, source checkout
        if candidate.is_dir():
            return candidate
    raise RobotDescriptionError(f"kinlearn's bundled robots/ folder is missing (looked in {here})")


def _example_robot_data_dir() -> Path:
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError as exc:
        raise RobotDescriptionError(
            "example-robot-data is not installed; `pip install example-robot-data` to load its arms"
        ) from exc
    marker = "share/example-robot-data/robots/"
    for f in dist.files or ():
        text = str(f).replace("\\", "/")
        if marker in text:
            root = text[: text.index(marker) + len(marker)]
            path = Path(str(dist.locate_file(root)))
            if path.is_dir():
                return path
    raise RobotDescriptionError(f"example-robot-data {dist.version} is installed but holds no {marker}")


def _floats(text: str | None, n: int, default: float, what: str) -> list[float]:
    """``n`` finite numbers from an attribute's text (``default`` each where it is absent);
    :class:`RobotDescriptionError` naming ``what`` for anything else."""
    if text is None:
        return [default] * n
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        values = []
    if len(values) != n or not all(math.isfinite(v) for v in values):
        raise RobotDescriptionError(f"{what}: expected {n} finite numbers, got {text!r}")
    return values


def _number(text: str | None, what: str, default: float | None = None) -> float:
    """One number from an attribute's text; :class:`RobotDescriptionError` naming ``what`` if it is none."""
    if text is None:
        if default is None:
            raise RobotDescriptionError(f"{what} is missing")
        return default
    try:
        return float(text)
    except ValueError:
        raise RobotDescriptionError(f"{what} must be a number, got {text!r}") from None


def _line_of(text: str, tag: str, name: str | None) -> str:
    """`` (line N)`` of the first ``<tag name="name"`` in the URDF's text, or nothing if not found."""
    pattern = rf"<{tag}\b[^>]*\bname\s*=\s*[\"']{re.escape(name or '')}[\"']"
    m = re.search(pattern, text)
    return f" (line {text.count(chr(10), 0, m.start()) + 1})" if m else ""


def validate_urdf(urdf: bytes, name: str) -> ET.Element:
    """The parsed URDF ``urdf`` of robot ``name``, checked as a kinematic tree; raises
    :class:`RobotDescriptionError` naming the element (and its line) for: XML that does not parse, a
    root that is no ``<robot>``, an unexpanded xacro expression (``${…}``, ``$(…)``: run xacro first), a
    link or joint without a name, duplicate link or joint names, a joint without ``<parent link>`` or
    ``<child link>``, or naming a link that is not declared, a link with two parent joints, a loop, or
    more than one root link. The chain's own numbers (origins, axes, limits) are checked where the
    chain is built (:class:`Robot`)."""
    try:
        root = ET.fromstring(urdf)
    except ET.ParseError as exc:
        raise RobotDescriptionError(f"{name}: the URDF is not valid XML: {exc}") from exc
    text = urdf.decode("utf-8", errors="replace")
    if root.tag != "robot":
        raise RobotDescriptionError(f"{name}: a URDF's root element is <robot>, this one's is <{root.tag}>")
    for el in root.iter():
        for key, value in el.attrib.items():
            if "${" in value or "$(" in value:
                where = _line_of(text, el.tag, el.get("name"))
                raise RobotDescriptionError(
                    f"{name}: <{el.tag}{' name=' + repr(el.get('name')) if el.get('name') else ''}>{where} holds "
                    f"the unexpanded xacro expression {key}={value!r}: run xacro on the file first "
                    "(`xacro robot.urdf.xacro > robot.urdf`)"
                )
    seen: dict[str, set[str]] = {"link": set(), "joint": set()}
    for tag in ("link", "joint"):
        for el in root.findall(tag):
            n = el.get("name")
            if not n:
                raise RobotDescriptionError(f"{name}: a <{tag}> without a name")
            if n in seen[tag]:
                raise RobotDescriptionError(f"{name}: two {tag}s are named {n!r}{_line_of(text, tag, n)}")
            seen[tag].add(n)
    links = seen["link"]
    parent_of: dict[str, str] = {}
    for el in root.findall("joint"):
        jname = el.get("name", "")  # every joint has a name: checked above
        ends = {}
        for end in ("parent", "child"):
            e = el.find(end)
            if e is None or not e.get("link"):
                raise RobotDescriptionError(
                    f"{name}: joint {jname!r}{_line_of(text, 'joint', jname)} has no <{end} link=...>"
                )
            if e.get("link") not in links:
                raise RobotDescriptionError(
                    f"{name}: joint {jname!r}{_line_of(text, 'joint', jname)} names {end} link "
                    f"{e.get('link')!r}, which the URDF does not declare as a <link>"
                )
            ends[end] = e.get("link", "")
        child = ends["child"]
        if child in parent_of:
            raise RobotDescriptionError(
                f"{name}: link {child!r} is the child of two joints, {parent_of[child]!r} and {jname!r}"
                f"{_line_of(text, 'joint', jname)}: a URDF is a tree, each link has one parent joint"
            )
        parent_of[child] = jname
    roots = sorted(links - set(parent_of))
    if len(roots) != 1:
        raise RobotDescriptionError(
            f"{name}: a URDF is a tree with one root link; "
            + (f"this one has {len(roots)}: {', '.join(roots[:10])}" if roots else "its joints form a loop")
        )
    return root


@dataclass(frozen=True)
class Joint:
    """One movable joint of the serial chain, with the fixed transform that precedes it.

    ``T_prev`` maps the previous movable joint's frame (or the chain's root) to this joint's frame
    at zero displacement: the product of any fixed joints in between and this joint's origin.
    """

    name: str
    kind: str  # "revolute" or "prismatic"
    axis: np.ndarray  # unit vector in the joint frame
    T_prev: np.ndarray  # (4, 4) float64
    lower: float
    upper: float
    velocity: float


class Robot:
    """A serial kinematic chain from a URDF's root link to an end-effector frame.

    Attributes: ``name``, ``urdf`` (the file's bytes), ``urdf_path``, ``root_link``, ``ee_frame``,
    ``joints`` (movable joints, base to tip), ``T_tip`` (last joint frame → end effector, float64),
    ``dof``, ``joint_names``, ``lower``/``upper``/``velocity_limits`` (float64 numpy arrays),
    ``path_origins`` (every joint on the root → end-effector path, fixed ones too: name → exact origin).
    """

    def __init__(self, name: str, urdf: bytes, ee_frame: str, urdf_path: Path | None = None):
        self.name = name
        self.urdf = urdf
        self.urdf_path = urdf_path
        self.ee_frame = ee_frame
        self.root_link, self.joints, self.T_tip, self.path_origins = _parse_chain(urdf, ee_frame, name)
        self.dof = len(self.joints)
        self.joint_names = tuple(j.name for j in self.joints)
        self.lower = np.array([j.lower for j in self.joints])
        self.upper = np.array([j.upper for j in self.joints])
        self.velocity_limits = np.array([j.velocity for j in self.joints])
        self.state_dim = self.dof + 3
        #: A spherized URDF giving the robot's collision body (``register_robot(..., spheres=PATH)``).
        self.sphere_urdf: Path | None = None

    def __repr__(self) -> str:
        return f"Robot({self.name!r}, dof={self.dof}, ee_frame={self.ee_frame!r})"

    def with_limits(self, lower: ArrayLike, upper: ArrayLike) -> Robot:
        """This robot (the same name, chain and URDF) with other position limits ``lower``/``upper``
        ``(dof,)``, or this very robot where they are its own: what a planner among obstacles checks and
        judges its problems with where its planning body's model allows more than the robot
        (:attr:`~kinlearn.collision.BodySpheres.outer_limits`)."""
        lo, hi = np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64)
        if lo.shape != (self.dof,) or hi.shape != (self.dof,) or not (lo < hi).all():
            raise ConfigError(
                f"limits must be two arrays of {self.dof} values with lower < upper for {self.name}"
            )
        if np.array_equal(lo, self.lower) and np.array_equal(hi, self.upper):
            return self
        other = copy.copy(self)
        other.lower, other.upper = lo, hi
        return other

    def limits(
        self, dtype: torch.dtype = torch.float32, device: torch.device | str | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Position limits as tensors ``(lower, upper)``, each of shape ``(dof,)``."""
        return (
            torch.as_tensor(self.lower, dtype=dtype, device=device),
            torch.as_tensor(self.upper, dtype=dtype, device=device),
        )

    def sample(
        self,
        shape: int | tuple[int, ...],
        generator: torch.Generator | None = None,
        dtype: torch.dtype = torch.float32,
        device: torch.device | str | None = None,
        margin: float = 0.0,
        limits: tuple[torch.Tensor, torch.Tensor] | None = None,
    ) -> torch.Tensor:
        """Joint configurations drawn uniformly within the limits (shrunk by ``margin`` rad on each side),
        or within ``limits`` ``(lower, upper)`` given instead (a body's narrower ones).

        Pass a seeded ``torch.Generator`` for reproducible samples.
        """
        shape = (shape,) if isinstance(shape, int) else tuple(shape)
        lo, hi = self.limits(dtype, device) if limits is None else limits
        lo, hi = lo + margin, hi - margin
        u = torch.rand((*shape, self.dof), generator=generator, dtype=dtype, device=device)
        return lo + (hi - lo) * u

    def within_limits(self, q: torch.Tensor, tol: float = 1e-6, limits: tuple | None = None) -> torch.Tensor:
        """``(...)`` bool: where configurations ``q (..., dof)`` stay within the position limits to ``tol``
        rad (NaN counts as outside), or within ``limits`` ``(lower, upper)`` given instead. A joint path is
        within them where ``within_limits(path).all(-1)``."""
        if limits is None:
            lo, hi = self.limits(q.dtype, q.device)
        else:
            lo, hi = (torch.as_tensor(np.asarray(x), dtype=q.dtype, device=q.device) for x in limits)
        return ((q >= lo - tol) & (q <= hi + tol)).all(-1)

    def check_joints(self, q: torch.Tensor, tol: float = 1e-6, what: str = "joint angles") -> None:
        """Raise :class:`JointLimitError` where ``q`` leaves the position limits by more than ``tol``."""
        check_last_dim(q, self.dof, what)
        check_finite(q, what)
        lo, hi = self.limits(q.dtype, q.device)
        bad = (q < lo - tol) | (q > hi + tol)
        if bool(bad.any()):
            idx = torch.nonzero(bad)[0].tolist()
            j = idx[-1]
            raise JointLimitError(
                f"{what} outside {self.name}'s limits: joint {self.joint_names[j]} = {float(q[tuple(idx)]):.6g} "
                f"rad at index {tuple(idx[:-1])}; allowed [{self.lower[j]:.6g}, {self.upper[j]:.6g}] rad"
            )


def _origin(el: ET.Element | None, what: str) -> np.ndarray:
    T = np.eye(4)
    if el is None:
        return T
    xyz = _floats(el.get("xyz"), 3, 0.0, f"{what} origin xyz")
    rpy = _floats(el.get("rpy"), 3, 0.0, f"{what} origin rpy")
    T[:3, :3] = rpy_matrix(*rpy)
    T[:3, 3] = xyz
    return T


def _parse_chain(
    urdf: bytes, ee_frame: str, name: str
) -> tuple[str, tuple[Joint, ...], np.ndarray, dict[str, np.ndarray]]:
    root = validate_urdf(urdf, name)
    links = {el.get("name", "") for el in root.findall("link")}  # validate_urdf: every one named
    by_child: dict[str, ET.Element] = {}
    for el in root.findall("joint"):
        child = el.find("child")
        if child is not None:
            by_child[child.get("link", "")] = el
    if ee_frame not in links:
        shown = ", ".join(sorted(links)[:40])
        raise RobotDescriptionError(
            f"{name}: end-effector frame {ee_frame!r} is not a link of this URDF; links are: {shown}"
        )
    # Walk from the end effector up to the root, then reverse.
    path: list[ET.Element] = []
    link = ee_frame
    while link in by_child:
        el = by_child[link]
        path.append(el)
        parent = el.find("parent")  # validate_urdf: every joint has one, naming a link
        link = "" if parent is None else parent.get("link", "")
        if len(path) > len(by_child):
            raise RobotDescriptionError(f"{name}: the URDF's joints form a loop")
    root_link = link
    path.reverse()

    joints: list[Joint] = []
    origins: dict[str, np.ndarray] = {}
    T_acc = np.eye(4)
    for el in path:
        jname, jtype = el.get("name", ""), el.get("type")
        origins[jname] = _origin(el.find("origin"), f"joint {jname}")
        T_acc = T_acc @ origins[jname]
        if jtype == "fixed":
            continue
        if jtype not in ("revolute", "continuous", "prismatic"):
            raise RobotDescriptionError(f"{name}: joint {jname} has unsupported type {jtype!r}")
        if el.find("mimic") is not None:
            raise RobotDescriptionError(f"{name}: joint {jname} on the chain mimics another; not supported")
        axis_el = el.find("axis")
        # The URDF default axis is x.
        axis = np.array(
            _floats(None if axis_el is None else axis_el.get("xyz"), 3, 0.0, f"joint {jname} axis")
        )
        axis = np.array([1.0, 0.0, 0.0]) if axis_el is None else axis
        norm = float(np.linalg.norm(axis))
        if norm == 0.0:
            raise RobotDescriptionError(f"{name}: joint {jname} has a zero axis")
        limit = el.find("limit")
        if jtype == "continuous":
            lower, upper = -math.pi, math.pi
        elif limit is None or limit.get("lower") is None or limit.get("upper") is None:
            raise RobotDescriptionError(f"{name}: joint {jname} has no position limits")
        else:
            what = f"{name}: joint {jname}'s limit"
            lower = _number(limit.get("lower"), f"{what} lower")
            upper = _number(limit.get("upper"), f"{what} upper")
            if not (math.isfinite(lower) and math.isfinite(upper) and lower < upper):
                raise RobotDescriptionError(
                    f"{what}s must be finite with lower < upper, got lower={limit.get('lower')!r}, "
                    f"upper={limit.get('upper')!r}"
                )
        velocity = math.inf
        if limit is not None:
            velocity = _number(limit.get("velocity"), f"{name}: joint {jname}'s velocity limit", math.inf)
            if math.isnan(velocity) or velocity <= 0:
                raise RobotDescriptionError(
                    f"{name}: joint {jname}'s velocity limit must be > 0, got {limit.get('velocity')!r}"
                )
        joints.append(
            Joint(
                jname,
                "prismatic" if jtype == "prismatic" else "revolute",
                axis / norm,
                T_acc,
                lower,
                upper,
                velocity,
            )
        )
        T_acc = np.eye(4)
    if not joints:
        raise RobotDescriptionError(f"{name}: no movable joint between the root and {ee_frame!r}")
    return root_link, tuple(joints), T_acc, origins


_CACHE: dict[tuple[str, str], Robot] = {}


def load_robot(name_or_path: str | Path, ee_frame: str | None = None) -> Robot:
    """Load a robot by name (see :data:`ROBOTS`) or from a URDF file path.

    A URDF path needs ``ee_frame``, the name of the link that is the end effector. Named robots are
    cached: loading the same one twice returns the same object.
    """
    key = (str(name_or_path), ee_frame or "")
    if key in _CACHE:
        return _CACHE[key]
    text = str(name_or_path)
    if text in ROBOTS:
        spec = ROBOTS[text]
        if spec.source == "file":
            path = Path(spec.relpath)
        else:
            base = _bundled_dir() if spec.source == "bundled" else _example_robot_data_dir()
            path = base / spec.relpath
        if not path.is_file():
            raise RobotDescriptionError(f"robot {text!r}: its URDF {path} is missing from the installation")
        robot = Robot(text, path.read_bytes(), ee_frame or spec.ee_frame, path)
    elif text.lower().endswith(".urdf") or Path(text).is_file():
        path = Path(text)
        if not path.is_file():
            raise UnknownRobotError(f"no URDF file at {path}")
        if ee_frame is None:
            raise RobotDescriptionError(f"loading {path} needs ee_frame=<name of the end-effector link>")
        robot = Robot(path.stem, path.read_bytes(), ee_frame, path)
    else:
        raise UnknownRobotError(
            f"unknown robot {text!r}; valid names are {', '.join(available_robots())}, or a path to a .urdf file"
        )
    _CACHE[key] = robot
    return robot
