"""Every error and warning kinlearn raises or emits on purpose, and when.

Errors derive from :class:`KinlearnError` (and from the built-in exception a caller would expect:
``ValueError`` for a bad value, ``KeyError`` for an unknown name, ...), so ``except KinlearnError``
catches all of them. Every error says what was wrong and what is allowed.

Warnings derive from :class:`KinlearnWarning`, so one filter silences or escalates all of them::

    import warnings
    import kinlearn
    warnings.simplefilter("error", kinlearn.KinlearnWarning)   # make every kinlearn warning an error
    warnings.simplefilter("ignore", kinlearn.KinlearnWarning)  # or silence them all
"""

from __future__ import annotations


class KinlearnError(Exception):
    """Base class of every error raised on purpose by kinlearn."""


class UnknownRobotError(KinlearnError, KeyError):
    """A robot name that is neither bundled nor a path to a URDF file."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class RobotDescriptionError(KinlearnError, ValueError):
    """A URDF that cannot be turned into a serial chain (missing frame, bad joint, ...)."""


class ShapeError(KinlearnError, ValueError):
    """A tensor or array of the wrong shape."""


class NonFiniteError(KinlearnError, ValueError):
    """An input holding NaN or infinity."""


class JointLimitError(KinlearnError, ValueError):
    """Joint values outside the robot's position limits."""


class CheckpointError(KinlearnError):
    """A checkpoint that is corrupt, of another format version, or of another robot."""


class DatasetError(KinlearnError):
    """A dataset file that is corrupt, of another format version, or of another robot."""


class RecordedDataError(DatasetError):
    """A recorded log (``.npz``/``.csv`` of joint values and end-effector positions) that cannot be used:
    missing columns, wrong joint count, non-numbers, NaN rows, wrong units, unsorted time, ..."""


class ConfigError(KinlearnError, ValueError):
    """A configuration value outside what is allowed."""


class StateError(KinlearnError, ValueError):
    """A state s = [θ, ef] whose end-effector part does not match the forward kinematics of its joints."""


class MissingDependencyError(KinlearnError, ImportError):
    """An optional dependency (an extra such as ``ompl`` or ``ray``) that is not installed."""


class PlanningError(KinlearnError, RuntimeError):
    """A planner found no solution for a query."""


class TrainingDivergedError(ConfigError):
    """Training produced a non-finite loss (usually: the learning rate is too high)."""


class TimingError(PlanningError):
    """A joint path that could not be time-parameterised within the given limits."""


class UnsafeTrajectoryError(TimingError):
    """The executed motion of a plan cannot be made collision-free: even along the plan's own straight
    segments, at rest at every waypoint, the timed samples collide (the joint path itself collides)."""


class RunDirectoryError(ConfigError):
    """A run directory that already holds a run: continue it (``--resume``, same configuration), replace it
    (``--overwrite``) or choose another one."""


class DTypeError(ShapeError, TypeError):
    """A tensor of a type that cannot hold the values asked for (bool or complex joint values, ...)."""


class ObstacleError(KinlearnError, ValueError):
    """Obstacles that cannot describe a scene: wrong shape, NaN/inf, a radius or half extent that is not > 0."""


class SceneFormatError(ObstacleError):
    """A scene or planning-request file (MoveIt YAML) that kinlearn cannot read: a missing or malformed
    field, or geometry it does not take (meshes, planes, cones), named by its object."""


class PointCloudError(ObstacleError):
    """A point cloud that cannot be planned among: not ``(N, 3)``, rows of NaN or infinity (unless dropped on
    request), no point, values that look like millimetres, a bad camera pose or cleaning option, or an
    extent too large for its grid (crop it)."""


class PointCloudFileError(PointCloudError, DatasetError):
    """A point-cloud file (``.npy``, ``.ply``, ``.pcd``) that cannot be read: missing, another suffix, a
    malformed header or body, no x, y, z fields, or fewer data than its header announces."""


class DomainError(KinlearnError, ValueError):
    """A start or goal outside the domain the planner was trained on (raised with ``strict=True``)."""


class BatchIndexError(ShapeError, IndexError, TypeError):
    """An index outside a batch (out of range, or reaching past its batch dimensions), or ``len()`` of an
    unbatched one. An IndexError too, so that iterating over a batch stops where it should."""


class OutputError(KinlearnError, OSError):
    """An output file that cannot be written: a folder in its place, a file where its folder should be, no
    permission, a read-only or full disk. The message names the path and what to do."""


class KinlearnWarning(UserWarning):
    """Base class of every warning kinlearn emits: filter on it to silence or escalate them all."""


class KinlearnDeprecationWarning(KinlearnWarning, DeprecationWarning):
    """A name that moved (``kinlearn.<old>`` → its home module, a baseline's old name): it still resolves,
    for one release, and the message names where it went. Emitted on each use of the old name."""


class DroppedRowsWarning(KinlearnWarning):
    """A recorded log read with rows holding NaN or infinity: those rows are dropped (the message names
    how many and which), and the gap they leave is never bridged by a transition."""


class NoObstacleModelWarning(KinlearnWarning):
    """Planning around obstacles for an arm whose planner has no obstacle-trained network: the plan comes
    from the straight joint line and bounded refinement alone (its ``collision_free`` says how it went)."""


class UnverifiedCheckpointWarning(KinlearnWarning):
    """A checkpoint of format 1, which carries no content hash: it loads, but tampering or corruption of its
    weights cannot be detected. Save it again (it then records its hash), or load with ``strict=True``
    to refuse it."""


class ObstaclesIgnoredWarning(KinlearnWarning):
    """A problem with obstacles given to a baseline that plans as in free space (its ``avoids_obstacles``
    is False): the plan does not avoid them; it is checked among them and says whether it collides."""


class CollidingEndWarning(KinlearnWarning):
    """A plan among obstacles that no stage could make collision-free because its start or its goal
    configuration itself collides (with the scene or with the arm itself) before any motion; the message
    names the problems and, where the scene overlaps the robot's fixed base (a surface it stands on given
    as a box), says so."""


class EndContactWarning(KinlearnWarning):
    """A plan among a point cloud whose start or goal touches the points' balls with no point deeper inside
    the arm's body than the cloud's ``contact``: it is taken to touch the surface the points sample, and
    the points within a few millimetres of its body there are dropped for the plan
    (:mod:`kinlearn.collision.cloud_contact`). The message names the end and the depth."""


class BeyondLimitsWarning(KinlearnWarning):
    """A plan among obstacles whose start or goal lies outside the robot's own joint limits but within
    those of the model its planning body was read from (MoveIt's panda, the standard benchmarks', turns up
    to 0.07 rad further than the Franka datasheet limits of kinlearn's panda): it is planned within the
    model's limits, where the robot itself may not go."""


class DomainWarning(KinlearnWarning):
    """A start or goal outside the domain the planner was trained on: its plan may be poor."""


class UnidentifiableError(DatasetError):
    """Observations that cannot identify a chain: a joint that never moves (named), fewer distinct samples
    than the chain's parameters need (duplicate rows count once), or a sample budget that leaves too few.
    Record motion of every joint, or give more distinct samples."""


class PoorExcitationWarning(KinlearnWarning):
    """An identification whose data determine some of the chain's parameters poorly or not at all (the
    parameter Jacobian loses rank along them): the joints named moved too little or only together, so the
    chain is right where the data were taken and may be far off elsewhere. Record wider motion of them."""
