"""Time parameterisation of a joint path: time stamps, velocities and accelerations within limits.

A plan is a geometric joint path θ(0) … θ(T) without time. :func:`time_parameterize` turns it into a
:class:`TimedTrajectory` that a position-controlled arm can execute: samples ``t, q, qd, qdd`` that
start and end at rest, pass through every waypoint, and keep every joint within its velocity and
acceleration limits.

**Library: toppra** (TOPP-RA, time-optimal path parameterisation by reachability analysis). The
problem here is *path* following: the geometry is fixed by the planner and only the timing along it
is free. toppra solves exactly that — the fastest traversal of a given path under joint velocity and
acceleration limits, rest to rest — as a sequence of small linear programs over a grid of path
positions. ruckig solves a different problem: jerk-limited state-to-state motions that do not follow
a prescribed path between two states; its open-source edition has no intermediate waypoints (those
need its commercial edition or its cloud service, i.e. the network). So ruckig would leave the
planned path, and toppra keeps it.

**The path through the waypoints.** Linear segments between waypoints have velocity corners, and a
time-optimal parameterisation must stop at each corner. The waypoints are instead joined by a smooth
interpolant over the cumulative joint-space chord length ``s``:

- ``"spline"``: toppra's cubic spline (C², not-a-knot ends). It is the smoothest, but a cubic may
  overshoot between waypoints, and near a joint limit it may leave the limits.
- ``"pchip"``: a shape-preserving piecewise-cubic Hermite interpolant (C¹, scipy's PCHIP). Between
  two waypoints each joint stays within the two waypoint values, so a path whose waypoints are
  within the limits stays within them.
- ``"auto"`` (default): the spline, checked densely against the position limits; where it leaves
  them, PCHIP. :attr:`TimedTrajectory.interpolant` records which one was used. Asking for
  ``"spline"`` explicitly on a path it cannot follow within the limits raises
  :class:`~kinlearn.errors.JointLimitError`.

A collinear run of equally spaced waypoints (joint interpolation) stays a straight line under both.

**Limits.** Velocity limits default to the URDF's ``<limit velocity=...>`` (``Robot.velocity_limits``),
scaled by ``velocity_scale``. URDFs carry no acceleration limits; the default is
``velocity_limits / DEFAULT_ACCELERATION_TIME`` (full speed reached in 0.5 s, before scaling), or pass
one value in rad/s² for every joint, or one per joint. toppra imposes the limits at its grid points;
between them a discretised solution can exceed a limit slightly (by several percent with PCHIP, whose
second derivative jumps at waypoints), so the result is checked on a dense sample of every grid
interval and, where it exceeds a limit, solved again with that limit tightened by the excess, until it
is within 1e-6 (relative) on the check. Positions are clipped to the position limits, which moves a
spline sample by at most the 1e-9 rad the limit check tolerates.
"""

from __future__ import annotations

import csv
import itertools
import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch

from ..body.robot import Robot
from ..checks import as_int, as_real
from ..errors import (
    ConfigError,
    DatasetError,
    JointLimitError,
    NonFiniteError,
    ShapeError,
    TimingError,
    UnsafeTrajectoryError,
)
from ..io import atomic_write

__all__ = ["DEFAULT_ACCELERATION_TIME", "TimedTrajectory", "time_parameterize"]

DEFAULT_ACCELERATION_TIME = 0.5  # s: default acceleration limit = velocity limit / this
DEFAULT_DT = 0.01  # s: default sample period (100 Hz)
TIMED_FORMAT = 1
_KIND = "kinlearn.timed_trajectory"
_DUPLICATE_TOL = 1e-9  # rad: consecutive waypoints closer than this are one waypoint
_LIMIT_RTOL = 1e-6  # relative excess of a limit that is accepted at the dense check
_GRID_PER_SEGMENT = 16  # toppra grid points per waypoint segment (at least)
_GRID_MIN = 200
_CHECK_PER_INTERVAL = 4  # dense-check samples per toppra grid interval
_MAX_RESOLVES = 6
#: The most samples a timed trajectory may have (t, q, qd, qdd: ≈ 24 · dof bytes each, 170 MB for 7
#: joints): ``samples`` above it, or a ``dt`` that would give more over the trajectory's duration
#: (tiny limits make it long), is refused before anything is allocated.
MAX_SAMPLES = 1_000_000

Interpolant = Literal["auto", "spline", "pchip"]


@dataclass(frozen=True, eq=False)
class TimedTrajectory:
    """A time-parameterised joint trajectory, sampled; SI units, float64 numpy arrays (read-only).

    Attributes:
        t: ``(K,)`` sample times from 0 to ``duration``, strictly increasing.
        q, qd, qdd: ``(K, dof)`` joint positions (rad), velocities (rad/s), accelerations (rad/s²).
        duration: total time (s); ``t[-1] == duration``.
        robot: the robot's name; ``joint_names``: its movable joints, base to tip (``dof`` names).
        velocity_limits, acceleration_limits: ``(dof,)`` the limits the trajectory was timed under.
        waypoint_times: ``(N,)`` the time at which the trajectory passes each input waypoint.
        interpolant: ``"spline"``, ``"pchip"`` or ``"linear"`` (the polyline itself, at rest at each
            waypoint), the path through the waypoints (module docstring); ``"mixed"`` where a repaired
            trajectory joins pieces of more than one.
        verified: whether the executed motion (these samples) was verified against a scene and body
            (:meth:`~kinlearn.planning.plan.Plan.timed` of a plan among obstacles).
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    duration: float
    robot: str
    joint_names: tuple[str, ...]
    velocity_limits: np.ndarray
    acceleration_limits: np.ndarray
    waypoint_times: np.ndarray
    interpolant: str
    verified: bool = False

    def __post_init__(self) -> None:
        for name in ("t", "q", "qd", "qdd", "velocity_limits", "acceleration_limits", "waypoint_times"):
            arr = np.array(getattr(self, name), dtype=np.float64)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "joint_names", tuple(self.joint_names))
        object.__setattr__(self, "duration", float(self.duration))
        k, dof = self.t.shape[0], len(self.joint_names)
        for name in ("q", "qd", "qdd"):
            if getattr(self, name).shape != (k, dof):
                raise ShapeError(
                    f"TimedTrajectory.{name} must have shape ({k}, {dof}), got {getattr(self, name).shape}"
                )
        if self.velocity_limits.shape != (dof,) or self.acceleration_limits.shape != (dof,):
            raise ShapeError(f"TimedTrajectory limits must have shape ({dof},)")
        for name in ("t", "q", "qd", "qdd", "velocity_limits", "acceleration_limits", "waypoint_times"):
            if not np.isfinite(getattr(self, name)).all():
                raise NonFiniteError(f"TimedTrajectory.{name} holds NaN/inf; every value must be finite")
        if not math.isfinite(self.duration) or self.duration < 0:
            raise ConfigError(f"TimedTrajectory.duration must be a finite time ≥ 0 s, got {self.duration}")
        t, wt = self.t, self.waypoint_times
        if self.t.ndim != 1 or k == 0 or t[0] != 0.0 or (np.diff(t) <= 0).any() or t[-1] != self.duration:
            raise ConfigError(
                "TimedTrajectory.t must be sample times increasing strictly from 0 to its duration "
                f"({self.duration:g} s)"
            )
        if wt.ndim != 1 or (np.diff(wt) < 0).any() or (wt.size and (wt[0] < 0 or wt[-1] > self.duration)):
            raise ConfigError(
                "TimedTrajectory.waypoint_times must not decrease and must lie within [0, duration]"
            )

    @property
    def dof(self) -> int:
        return len(self.joint_names)

    def __len__(self) -> int:
        return self.t.shape[0]

    def __repr__(self) -> str:
        return (
            f"TimedTrajectory(robot={self.robot!r}, samples={len(self)}, duration={self.duration:.4g} s, "
            f"interpolant={self.interpolant!r})"
        )

    # ------------------------------------------------------------------ files

    def to_csv(self, path: str | Path) -> Path:
        """Write one row per sample: ``t, q_<joint>…, qd_<joint>…, qdd_<joint>…`` (header row first).

        Values are written with 17 significant digits, so reading them back gives the same floats.
        """
        header = ["t"] + [f"{p}_{j}" for p in ("q", "qd", "qdd") for j in self.joint_names]
        table = np.concatenate([self.t[:, None], self.q, self.qd, self.qdd], axis=1)

        def write(tmp: Path) -> None:
            with tmp.open("w", newline="") as f:
                writer = csv.writer(f)
                writer.writerow(header)
                writer.writerows([[f"{v:.17g}" for v in row] for row in table])

        return atomic_write(path, write)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able dict of every field plus a format version."""
        return {
            "format": TIMED_FORMAT,
            "kind": _KIND,
            "robot": self.robot,
            "joint_names": list(self.joint_names),
            "interpolant": self.interpolant,
            "verified": self.verified,
            "duration": self.duration,
            "velocity_limits": self.velocity_limits.tolist(),
            "acceleration_limits": self.acceleration_limits.tolist(),
            "waypoint_times": self.waypoint_times.tolist(),
            "t": self.t.tolist(),
            "q": self.q.tolist(),
            "qd": self.qd.tolist(),
            "qdd": self.qdd.tolist(),
        }

    def to_json(self, path: str | Path) -> Path:
        """Write :meth:`to_dict` as JSON, atomically; floats round-trip exactly."""
        text = json.dumps(self.to_dict()) + "\n"

        def write(tmp: Path) -> None:
            tmp.write_text(text)

        return atomic_write(path, write)

    @classmethod
    def from_json(cls, path: str | Path) -> TimedTrajectory:
        """Read a file written by :meth:`to_json`; :class:`DatasetError` if it is not one."""
        path = Path(path)
        try:
            obj = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise DatasetError(f"{path}: cannot read a timed trajectory ({exc})") from exc
        if not isinstance(obj, dict) or obj.get("kind") != _KIND:
            raise DatasetError(f"{path} is not a kinlearn timed trajectory (no kind {_KIND!r})")
        if obj.get("format") != TIMED_FORMAT:
            raise DatasetError(
                f"{path}: timed-trajectory format {obj.get('format')!r}; this kinlearn reads format {TIMED_FORMAT}"
            )
        try:
            fields = {k: obj[k] for k in cls.__dataclass_fields__ if k != "verified"}
            fields["verified"] = bool(obj.get("verified", False))
            dof = len(fields["joint_names"])
            for name in ("q", "qd", "qdd"):  # an empty trajectory would lose its second dimension
                fields[name] = np.asarray(fields[name], dtype=np.float64).reshape(-1, dof)
            return cls(**fields)
        except (KeyError, TypeError, ValueError) as exc:
            raise DatasetError(f"{path}: malformed timed trajectory ({exc})") from exc


# ---------------------------------------------------------------------------------------------- inputs


def _limit_vector(value: Any, dof: int, what: str) -> np.ndarray:
    if isinstance(value, torch.Tensor):
        value = value.detach().cpu().double().numpy()
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        arr = np.full(dof, float(arr))
    if arr.shape != (dof,):
        raise ShapeError(f"{what} must be one number or {dof} numbers (one per joint), got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise NonFiniteError(f"{what} must be finite, got {arr.tolist()}")
    if (arr <= 0).any():
        raise ConfigError(f"{what} must be positive for every joint, got {arr.tolist()}")
    return arr


def _resolve_limits(
    robot: Robot, velocity_limits: Any, acceleration_limits: Any, velocity_scale: float
) -> tuple[np.ndarray, np.ndarray]:
    velocity_scale = as_real(velocity_scale, "velocity_scale", minimum=0.0, open_minimum=True, maximum=1.0)
    if velocity_limits is None:
        vel = np.asarray(robot.velocity_limits, dtype=np.float64)
        missing = [n for n, v in zip(robot.joint_names, vel, strict=True) if not math.isfinite(v) or v <= 0]
        if missing:
            raise ConfigError(
                f"{robot.name}'s URDF gives no usable velocity limit for joint(s) {', '.join(missing)}; "
                "pass velocity_limits= (rad/s, one number or one per joint)"
            )
    else:
        vel = _limit_vector(velocity_limits, robot.dof, "velocity_limits (rad/s)")
    if acceleration_limits is None:
        acc = vel / DEFAULT_ACCELERATION_TIME
    else:
        acc = _limit_vector(acceleration_limits, robot.dof, "acceleration_limits (rad/s²)")
    return vel * float(velocity_scale), acc


def _joint_path(robot: Robot, joints: Any) -> np.ndarray:
    if isinstance(joints, np.ndarray):
        joints = torch.from_numpy(np.array(joints, dtype=np.float64))
    if not isinstance(joints, torch.Tensor):
        raise ShapeError(
            f"joints must be a tensor or array of shape (T + 1, {robot.dof}), got {type(joints).__name__}"
        )
    if joints.ndim != 2 or joints.shape[-1] != robot.dof or joints.shape[0] < 1:
        raise ShapeError(
            f"joints must have shape (T + 1, {robot.dof}) — one path, T + 1 ≥ 1 configurations of "
            f"{robot.name} — got {tuple(joints.shape)}; time a batch of plans one plan at a time"
        )
    robot.check_joints(joints, what="joint path")  # floating point, finite, within position limits
    return joints.detach().cpu().to(torch.float64).numpy().copy()


# ---------------------------------------------------------------------------------------------- paths


def _pchip_path(ss: np.ndarray, qs: np.ndarray):
    """A toppra geometric path through the waypoints by scipy's shape-preserving PCHIP."""
    from scipy.interpolate import PchipInterpolator
    from toppra.interpolator import AbstractGeometricPath

    class _PchipPath(AbstractGeometricPath):
        def __init__(self) -> None:
            self._ss, self._qs = ss, qs
            self._p = [PchipInterpolator(ss, qs, axis=0)]
            self._p += [self._p[0].derivative(1), self._p[0].derivative(2)]

        def __call__(self, path_positions, order: int = 0):
            return self._p[order](path_positions)

        @property
        def dof(self) -> int:
            return self._qs.shape[1]

        @property
        def path_interval(self) -> np.ndarray:
            return np.array([self._ss[0], self._ss[-1]])

        @property
        def waypoints(self):
            return self._ss, self._qs

    return _PchipPath()


def _inside_limits(path, ss: np.ndarray, robot: Robot, tol: float = 1e-9) -> bool:
    dense = np.linspace(ss[0], ss[-1], 64 * (len(ss) - 1) + 1)
    q = path(dense)
    return bool(((q >= robot.lower - tol) & (q <= robot.upper + tol)).all())


def _make_path(robot: Robot, ss: np.ndarray, qs: np.ndarray, interpolant: Interpolant):
    import toppra

    if interpolant in ("auto", "spline"):
        spline = toppra.SplineInterpolator(ss, qs, bc_type="not-a-knot")
        if _inside_limits(spline, ss, robot):
            return spline, "spline"
        if interpolant == "spline":
            raise JointLimitError(
                f"the cubic spline through these waypoints leaves {robot.name}'s joint position limits "
                "between waypoints; use interpolant='pchip' (stays within them) or 'auto'"
            )
    return _pchip_path(ss, qs), "pchip"


def _grid(ss: np.ndarray) -> np.ndarray:
    """Grid points for toppra: every waypoint, and evenly spaced points within each segment."""
    lengths = np.diff(ss)
    counts = np.maximum(_GRID_PER_SEGMENT, np.ceil(_GRID_MIN * lengths / ss[-1])).astype(int)
    inner = [a + (b - a) * np.arange(n) / n for a, b, n in zip(ss[:-1], ss[1:], counts, strict=True)]
    return np.concatenate([*inner, ss[-1:]])


def _solve(path, grid: np.ndarray, vel: np.ndarray, acc: np.ndarray):
    import toppra.algorithm as algo
    import toppra.constraint as constraint

    constraints = [
        constraint.JointVelocityConstraint(np.stack([-vel, vel], axis=1)),
        constraint.JointAccelerationConstraint(
            np.stack([-acc, acc], axis=1), discretization_scheme=constraint.DiscretizationType.Interpolation
        ),
    ]
    solver = algo.TOPPRA(
        constraints, path, gridpoints=grid, solver_wrapper="seidel", parametrizer="ParametrizeConstAccel"
    )
    traj = solver.compute_trajectory(0.0, 0.0)
    if traj is None:
        code = solver.problem_data.return_code
        raise TimingError(
            f"toppra found no parameterisation of the path within the limits (return code {code})"
        )
    return traj


def _evaluate(traj, ts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return traj(ts, 0), traj(ts, 1), traj(ts, 2)


def _excess(traj, vel: np.ndarray, acc: np.ndarray) -> tuple[float, float]:
    """The largest ratios |qd| / vel and |qdd| / acc over a dense sample of the trajectory.

    Every interval of toppra's grid is sampled at its start, inside, and just before its end: the
    path's second derivative may jump at a waypoint (PCHIP), and toppra sees only one side of it.
    """
    knots = np.asarray(traj._ts, dtype=np.float64)  # toppra's grid-point times
    frac = np.append(np.arange(_CHECK_PER_INTERVAL) / _CHECK_PER_INTERVAL, 1.0 - 1e-9)
    ts = (knots[:-1, None] + frac * np.diff(knots)[:, None]).ravel()
    ts = np.concatenate([ts, knots[-1:]])
    _, qd, qdd = _evaluate(traj, ts)
    return float(np.max(np.abs(qd) / vel)), float(np.max(np.abs(qdd) / acc))


def _sample_times(duration: float, dt: float | None, samples: int | None) -> np.ndarray:
    if samples is not None:
        return np.linspace(0.0, duration, samples)
    step = DEFAULT_DT if dt is None else dt
    ts = np.arange(0.0, duration, step)
    if duration - ts[-1] < 1e-9 * step:  # the end falls on the grid: do not add it twice
        ts = ts[:-1]
    return np.concatenate([ts, [duration]])


# ---------------------------------------------------------------------------------------------- public


#: Rounds of knots added where the executed motion leaves the checked corridor, before the motion is
#: brought to rest at the corners there (each round halves the knot spacing around every collision).
REFINE_ROUNDS = 5

#: What :func:`time_parameterize` calls to verify the executed motion: the sampled positions ``(K, dof)``
#: in, per sample interval ``(K − 1,)`` whether it collides (either end, or anywhere between) out.
Verifier = Callable[[np.ndarray], np.ndarray]


@dataclass
class _Piece:
    """A rest-to-rest stretch of the trajectory through knots ``(n, dof)``: its duration, the time it
    passes each knot, an evaluator ``ts → (q, qd, qdd)`` and the interpolant used."""

    duration: float
    knot_times: np.ndarray
    evaluate: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]
    interpolant: str


def _spline_piece(robot: Robot, qs: np.ndarray, interpolant: Interpolant, vel, acc) -> _Piece:
    """The time-optimal traversal of the smooth interpolant through ``qs`` (toppra); TimingError where
    toppra finds none or cannot bring the limits' excess within tolerance."""
    chord = np.linalg.norm(np.diff(qs, axis=0), axis=1)
    ss = np.concatenate([[0.0], np.cumsum(chord)])
    path, used = _make_path(robot, ss, qs, interpolant)
    grid = _grid(ss)
    v_solve, a_solve = vel, acc
    for _ in range(_MAX_RESOLVES):
        traj = _solve(path, grid, v_solve, a_solve)
        v_ratio, a_ratio = _excess(traj, vel, acc)
        if max(v_ratio, a_ratio) <= 1.0 + _LIMIT_RTOL:
            break
        # Discretisation let a limit be exceeded between grid points: tighten it by the excess.
        v_solve, a_solve = v_solve / max(v_ratio, 1.0), a_solve / max(a_ratio, 1.0)
    else:
        excess = 100 * (max(v_ratio, a_ratio) - 1)
        raise TimingError(
            f"the timed path still exceeds a limit by {excess:.3g}% after {_MAX_RESOLVES} solves; "
            "the path may have a near-corner: add waypoints or use interpolant='pchip'"
        )
    knot_times = np.asarray(traj._ts, dtype=np.float64)[np.searchsorted(grid, ss)]
    return _Piece(float(traj.duration), knot_times, lambda ts: _evaluate(traj, ts), used)


def _linear_piece(qs: np.ndarray, vel: np.ndarray, acc: np.ndarray) -> _Piece:
    """The polyline through ``qs`` itself, at rest at every vertex: each segment a → b is crossed along
    the straight line in the least time its limits allow (accelerate at the most any joint allows,
    cruise at the most velocity, decelerate: a trapezoid, or a triangle where the segment is short)."""
    starts, deltas, durations, shapes = [], [], [], []
    for a, b in itertools.pairwise(qs):
        d = b - a
        moving = np.abs(d) > 0
        v = float(np.min(vel[moving] / np.abs(d[moving])))  # path speed, segment lengths per second
        ac = float(np.min(acc[moving] / np.abs(d[moving])))
        if v * v / ac >= 1.0:  # never reaches full speed: a triangle
            ta = math.sqrt(1.0 / ac)
            shapes.append((ta, 0.0, ac, ac * ta))
            durations.append(2.0 * ta)
        else:
            ta = v / ac
            cruise = (1.0 - v * ta) / v
            shapes.append((ta, cruise, ac, v))
            durations.append(2.0 * ta + cruise)
        starts.append(a)
        deltas.append(d)
    offsets = np.concatenate([[0.0], np.cumsum(durations)])

    def evaluate(ts: np.ndarray):
        k = np.clip(np.searchsorted(offsets, ts, side="right") - 1, 0, len(durations) - 1)
        u = np.clip(ts - offsets[k], 0.0, None)
        s, sd, sdd = np.empty_like(ts), np.empty_like(ts), np.empty_like(ts)
        for i, (ta, cruise, ac, top) in enumerate(shapes):
            m = k == i
            x = np.minimum(u[m], durations[i])
            rise, flat, fall = x < ta, (x >= ta) & (x < ta + cruise), x >= ta + cruise
            y = np.where(rise, 0.5 * ac * x * x, 0.0)
            y = np.where(flat, 0.5 * ac * ta * ta + top * (x - ta), y)
            back = durations[i] - x
            y = np.where(fall, 1.0 - 0.5 * ac * back * back, y)
            s[m] = y
            sd[m] = np.where(rise, ac * x, np.where(flat, top, ac * back))
            sdd[m] = np.where(rise, ac, np.where(flat, 0.0, -ac))
        a, d = np.asarray(starts)[k], np.asarray(deltas)[k]
        return a + s[:, None] * d, sd[:, None] * d, sdd[:, None] * d

    return _Piece(float(offsets[-1]), offsets.copy(), evaluate, "linear")


def _piece(robot: Robot, qs: np.ndarray, interpolant: Interpolant, vel, acc, straight: bool) -> _Piece:
    """A piece through ``qs``: the smooth interpolant (two knots: the straight segment), or the polyline
    at rest at its vertices where ``straight`` or where toppra finds no parameterisation."""
    if straight or len(qs) == 2:
        return _linear_piece(qs, vel, acc)
    try:
        return _spline_piece(robot, qs, interpolant, vel, acc)
    except TimingError:
        if interpolant == "spline":
            raise
        return _linear_piece(qs, vel, acc)


def _assemble(
    pieces: list[_Piece], dt, samples
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float, np.ndarray]:
    """Samples ``(t, q, qd, qdd)`` of the pieces one after the other (at rest between them), and the time
    each knot is passed (the knot shared by two pieces once)."""
    offsets = np.concatenate([[0.0], np.cumsum([p.duration for p in pieces])])
    duration = float(offsets[-1])
    step = DEFAULT_DT if dt is None else dt
    if samples is None and duration / step + 2 > MAX_SAMPLES:
        raise ConfigError(
            f"sampling the {duration:.4g} s trajectory every {step:g} s would take {duration / step:.3g} samples, "
            f"more than the {MAX_SAMPLES:,} allowed (MAX_SAMPLES: the arrays would not fit in memory); "
            "pass a larger dt or samples=, or larger velocity/acceleration limits"
        )
    ts = _sample_times(duration, dt, samples)
    which = np.clip(np.searchsorted(offsets, ts, side="right") - 1, 0, len(pieces) - 1)
    dof = None
    q = qd = qdd = None
    for i, p in enumerate(pieces):
        m = which == i
        if not m.any():
            continue
        local = np.clip(ts[m] - offsets[i], 0.0, p.duration)
        a, b, c = p.evaluate(local)
        if q is None or qd is None or qdd is None:  # the first piece with samples (made together)
            dof = a.shape[1]
            q, qd, qdd = (np.empty((len(ts), dof)) for _ in range(3))
        q[m], qd[m], qdd[m] = a, b, c
    # every sample time falls in some piece (the last sample is at the duration): q, qd, qdd are made
    assert q is not None and qd is not None and qdd is not None
    knot_times = [pieces[0].knot_times]
    knot_times += [p.knot_times[1:] + offsets[i] for i, p in enumerate(pieces) if i > 0]
    return ts, q, qd, qdd, duration, np.concatenate(knot_times)


def _bad_knots(bad: np.ndarray, ts: np.ndarray, knot_times: np.ndarray) -> np.ndarray:
    """The knot intervals ``(n − 1,)`` that the colliding sample intervals ``bad (K − 1,)`` overlap."""
    out = np.zeros(len(knot_times) - 1, dtype=bool)
    for k in np.flatnonzero(bad):
        lo = max(int(np.searchsorted(knot_times, ts[k], side="right")) - 1, 0)
        hi = min(int(np.searchsorted(knot_times, ts[k + 1], side="left")), len(knot_times) - 1)
        out[lo : max(hi, lo + 1)] = True
    return out


# ---------------------------------------------------------------------------------------------- public


def time_parameterize(
    robot: Robot,
    joints: torch.Tensor | np.ndarray,
    *,
    velocity_limits: float | np.ndarray | torch.Tensor | None = None,
    acceleration_limits: float | np.ndarray | torch.Tensor | None = None,
    velocity_scale: float = 1.0,
    dt: float | None = None,
    samples: int | None = None,
    interpolant: Interpolant = "auto",
    verify: Verifier | None = None,
) -> TimedTrajectory:
    """The time-optimal rest-to-rest trajectory along a joint path, within velocity/acceleration limits,
    its executed motion verified where ``verify`` is given.

    Args:
        robot: the robot the path belongs to (its joint names, position and velocity limits).
        joints: ``(T + 1, dof)`` one joint path (rad), e.g. ``plan.joints`` of a single plan; every
            configuration within the position limits. Consecutive repeated configurations count once.
        velocity_limits: rad/s, one number or ``(dof,)``; default: the URDF's velocity limits.
        acceleration_limits: rad/s², one number or ``(dof,)``; default: velocity limits (unscaled)
            divided by :data:`DEFAULT_ACCELERATION_TIME` (0.5 s).
        velocity_scale: factor in (0, 1] applied to the velocity limits (not the accelerations).
        dt: sample period in s (default 0.01 s); the last sample is always at ``duration``.
        samples: number of samples from 0 to ``duration`` inclusive (≥ 2), instead of ``dt``.
        interpolant: ``"auto"``, ``"spline"`` or ``"pchip"``: the smooth path through the waypoints
            (see the module docstring).
        verify: a check of the executed motion (:data:`Verifier`: the samples in, the colliding sample
            intervals out; :meth:`~kinlearn.planning.plan.Plan.timed` passes the dense check of the
            plan's own scene and body). Where the samples collide, the path is repaired and timed
            again (see the module docstring) until they pass.

    Returns:
        A :class:`TimedTrajectory`. A path whose configurations are all the same gives one sample at
        rest with duration 0.

    Raises:
        ShapeError, NonFiniteError, JointLimitError: a malformed path, or one outside the limits.
        ConfigError: non-positive limits, a velocity_scale outside (0, 1], a bad dt/samples/interpolant.
        TimingError: ``interpolant="spline"`` and toppra found no parameterisation.
        UnsafeTrajectoryError: ``verify`` still finds a collision when the motion follows the path's
            own straight segments (the path itself collides).
    """
    if interpolant not in ("auto", "spline", "pchip"):
        raise ConfigError(f"interpolant must be 'auto', 'spline' or 'pchip', got {interpolant!r}")
    if dt is not None and samples is not None:
        raise ConfigError("give dt or samples, not both")
    if dt is not None:
        dt = as_real(dt, "dt (s)", minimum=0.0, open_minimum=True)
    if samples is not None:
        samples = as_int(samples, "samples", minimum=2, maximum=MAX_SAMPLES)
    q_in = _joint_path(robot, joints)
    vel, acc = _resolve_limits(robot, velocity_limits, acceleration_limits, velocity_scale)

    # Consecutive duplicates collapse into one waypoint.
    chord = np.linalg.norm(np.diff(q_in, axis=0), axis=1)
    keep = np.concatenate([[True], chord > _DUPLICATE_TOL])
    which = np.cumsum(keep) - 1  # input waypoint → index among the kept ones
    qs = q_in[keep]
    if len(qs) == 1:
        zeros = np.zeros((1, robot.dof))
        return TimedTrajectory(
            t=np.zeros(1), q=qs, qd=zeros, qdd=zeros, duration=0.0,
            waypoint_times=np.zeros(len(q_in)), interpolant="spline", verified=verify is not None,
            robot=robot.name, joint_names=robot.joint_names, velocity_limits=vel, acceleration_limits=acc,
        )  # fmt: skip

    # The knots: the waypoints, and points added on the polyline's own segments (so every knot and
    # every segment between consecutive knots lies on the path that was checked).
    knots, vertex = qs, np.arange(len(qs))  # vertex[i]: the knot index of waypoint i
    stops = {0, len(qs) - 1}  # knots the motion comes to rest at (piece boundaries)
    straight: set[int] = set()  # pieces (by their first knot) that follow the polyline itself
    round_ = 0
    while True:
        bounds = sorted(stops)
        pieces = [
            _piece(robot, knots[a : b + 1], interpolant, vel, acc, a in straight)
            for a, b in itertools.pairwise(bounds)
        ]
        ts, q, qd, qdd, duration, knot_times = _assemble(pieces, dt, samples)
        q[-1], qd[0], qd[-1] = knots[-1], 0.0, 0.0  # exact end configuration and rest
        q = np.clip(q, robot.lower, robot.upper)
        bad = None if verify is None else np.asarray(verify(q), dtype=bool)
        if bad is None or not bad.any():
            break
        intervals = _bad_knots(bad, ts, knot_times)
        if round_ < REFINE_ROUNDS:  # halve the knot spacing around each collision
            grow = intervals.copy()
            grow[1:] |= intervals[:-1]
            grow[:-1] |= intervals[1:]
            mids = (knots[:-1] + knots[1:]) / 2
            order = np.concatenate([np.arange(len(knots)), np.flatnonzero(grow) + 0.5])
            pos = np.argsort(order, kind="stable")
            knots = np.concatenate([knots, mids[grow]])[pos]
            new_index = np.empty(len(pos), dtype=np.int64)
            new_index[pos] = np.arange(len(pos))
            vertex = new_index[vertex]
            stops = {int(new_index[s]) for s in stops}
            straight = {int(new_index[s]) for s in straight}
        elif round_ == REFINE_ROUNDS:  # rest at the waypoints that bound each collision
            for i in np.flatnonzero(intervals):
                stops.add(int(vertex[max(np.searchsorted(vertex, i, side="right") - 1, 0)]))
                stops.add(int(vertex[min(np.searchsorted(vertex, i + 1, side="left"), len(vertex) - 1)]))
        else:  # the pieces still colliding follow the polyline itself
            bounds = sorted(stops)
            more = {
                bounds[max(np.searchsorted(bounds, i, side="right") - 1, 0)]
                for i in np.flatnonzero(intervals)
            }
            if more <= straight:  # they already do: the path itself collides
                raise UnsafeTrajectoryError(
                    f"the executed motion still collides in {int(bad.sum())} sample interval(s) when it "
                    "follows the path's own straight segments, at rest at every waypoint: the joint path itself collides "
                    "(plan.collision_free says whether the planner cleared it); nothing safe to execute"
                )
            straight |= more
        round_ += 1
    used = {p.interpolant for p in pieces}
    return TimedTrajectory(
        t=ts, q=q, qd=qd, qdd=qdd, duration=duration,
        waypoint_times=knot_times[vertex][which], interpolant=used.pop() if len(used) == 1 else "mixed",
        verified=verify is not None,
        robot=robot.name, joint_names=robot.joint_names, velocity_limits=vel, acceleration_limits=acc,
    )  # fmt: skip
