"""The obstacle-aware trajectory model: joint paths around obstacles, several candidates per problem.

The joint-path TM (:mod:`kinlearn.models.joint_path`) bends the straight joint line with a few sine modes per
joint; this model does the same, but it also sees the obstacles and proposes ``candidates`` paths at
once, each its own set of mode coefficients. The planner checks them (and the straight line) against
the scene and keeps a collision-free one, so a plan costs one network pass and a bounded number of
path checks whatever the problem: a fixed, small time.

The scene enters as a set. Every primitive (a sphere, a box or a cylinder) becomes a row of
features: its centre, its half extents (a sphere's radius three times; a rotated box's or a cylinder's
axis-aligned bounding box), whether it is a sphere, and
its centre relative to the start's and the goal's end effector. A small network maps each row to an
embedding and a masked max over the rows pools them (a PointNet-style set encoder), so scenes of any
number of primitives give an input of one size; a floor plane enters as its height and a flag. The
trunk, an MLP over the problem's features and the pooled scene, emits the candidates' coefficients.

Trained self-supervised (:mod:`kinlearn.training.obstacle_path`): no planner shows it a path.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import torch
from torch import nn

from ..body.state import StateLayout
from ..collision.geometry import aabb_half_extents, shape_tensor
from ..collision.scene import Scene
from ..errors import CheckpointError, ConfigError
from ..io import half_weights, load_checkpoint, save_checkpoint
from .joint_path import RobotModelConfig, mlp_layers, register_path_buffers

__all__ = [
    "MIN_STD",
    "PRIMITIVE_FEATURES",
    "ROW_WIDTH",
    "ObstaclePathConfig",
    "ObstaclePathModel",
    "export_obstacle_model",
    "load_obstacle_model",
    "save_obstacle_model",
    "scene_primitives",
]

#: Columns of a primitive's row (:func:`scene_primitives`): centre (3), the half extents of its
#: axis-aligned bounding box (3), is-sphere (1), its extent tensor (6,
#: :func:`~kinlearn.collision.geometry.shape_tensor`), is-cylinder (1).
ROW_WIDTH = 14
#: Features per scene primitive the encoder reads, per ``ObstaclePathConfig.primitives``: the row's
#: first 7 columns (``"aabb"``) or all 14 (``"shape"``), then centre − ef(0) (3) and centre − ef(T) (3).
#: Row columns of each choice, and the 0/1 flags among them (not standardised).
_COLUMNS = {"aabb": 7, "shape": ROW_WIDTH}
_FLAGS = {"aabb": (6,), "shape": (6, 13)}
PRIMITIVE_FEATURES = {k: cols + 6 for k, cols in _COLUMNS.items()}  # aabb 13, shape 20
#: The least standard deviation a feature is standardised with; a feature whose training spread was
#: below it never varied there, and the network holds it at its training mean
#: (:attr:`ObstaclePathModel.input_scales`).
MIN_STD = 1e-3


@dataclass(frozen=True)
class ObstaclePathConfig(RobotModelConfig):
    """Architecture of the obstacle-aware TM.

    ``steps``: T (T − 1 intermediate knots). ``modes``: sine modes per joint and candidate.
    ``candidates``: paths proposed per problem. ``encoder``: widths of the per-primitive network (the
    last is the pooled scene embedding's size). ``hidden``: widths of the trunk. ``lower``/``upper``:
    the joint limits (filled by :meth:`for_robot`). ``primitives``: what the encoder reads of each
    primitive: ``"shape"`` its extent tensor and kind besides its bounding box (which way a rotated box
    or a cylinder lies), ``"aabb"`` its bounding box alone (what the first shipped network reads; the
    value of a checkpoint that records none).
    """

    robot: str = "iiwa14"
    dof: int = 7
    steps: int = 11
    modes: int = 6
    candidates: int = 6
    encoder: tuple[int, ...] = (64, 128)
    hidden: tuple[int, ...] = (256, 256, 256)
    activation: Literal["tanh", "silu"] = "silu"
    primitives: Literal["aabb", "shape"] = "shape"
    lower: tuple[float, ...] = ()
    upper: tuple[float, ...] = ()

    @classmethod
    def from_dict(cls, d: dict):
        return super().from_dict({"primitives": "aabb", **d})  # files from before the choice read boxes

    def __post_init__(self) -> None:
        if self.primitives not in _COLUMNS:
            raise ConfigError(f"primitives must be 'aabb' or 'shape', got {self.primitives!r}")
        for name in ("steps", "dof", "modes", "candidates"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ConfigError(f"{name} must be a positive integer, got {v!r}")
        if self.steps < 2:
            raise ConfigError(f"steps (T) must be ≥ 2, got {self.steps}")
        for name in ("encoder", "hidden"):
            widths = getattr(self, name)
            if not widths or any(isinstance(w, bool) or not isinstance(w, int) or w < 1 for w in widths):
                raise ConfigError(f"{name} must be a non-empty tuple of positive widths, got {widths!r}")
        if self.activation not in ("tanh", "silu"):
            raise ConfigError(f"activation must be 'tanh' or 'silu', got {self.activation!r}")
        self._check_limits()


def scene_primitives(
    scene: Scene, batch: int, dtype=torch.float32
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """A scene as the model's set input for ``batch`` problems.

    Returns ``rows (batch, P, 14)`` [centre, bounding half extents, is-sphere, extent tensor,
    is-cylinder] (spheres first, then boxes, then cylinders; :data:`ROW_WIDTH`), ``mask (batch, P)``
    (False for padding) and ``floor (batch, 2)`` [has floor, height]. The bounding half extents are
    those of the axis-aligned bounding box (:func:`~kinlearn.collision.geometry.aabb_half_extents`: an
    axis-aligned box's own, so the first 7 columns of spheres and axis-aligned boxes are those the
    first shipped model was trained on); the extent tensor is
    :func:`~kinlearn.collision.geometry.shape_tensor`'s. The scene's batch shape must be ``()`` or
    ``(batch,)``.
    """
    if scene.batch_shape not in ((), (batch,)):
        raise ConfigError(
            f"the scene's batch shape {tuple(scene.batch_shape)} must be () or ({batch},) for {batch} problems"
        )
    key = (batch, dtype)
    if batch == 1 and scene.batch_shape == ():  # a batch-1 plan: the same rows on every call for this scene
        hit = _ROWS.get(scene, {}).get(key)
        if hit is not None:
            return hit
    parts, masks = [], []
    for kind, table, m in scene.tables():
        if table.shape[-2] == 0:  # nothing of this kind: no rows (and no work)
            continue
        t = table.to(dtype).expand(batch, *table.shape[-2:])
        sphere, cylinder = (torch.full_like(t[..., :1], flag) for flag in kind.network_flags)
        parts.append(
            torch.cat((t[..., :3], aabb_half_extents(kind, t), sphere, shape_tensor(kind, t), cylinder), -1)
        )
        masks.append(
            torch.ones(batch, t.shape[-2], dtype=torch.bool, device=t.device)
            if m is None
            else m.expand(batch, t.shape[-2])
        )
    if not parts:
        parts.append(torch.zeros(batch, 0, ROW_WIDTH, dtype=dtype, device=scene.device))
        masks.append(torch.zeros(batch, 0, dtype=torch.bool, device=scene.device))
    rows = torch.cat(parts, dim=1) if len(parts) > 1 else parts[0]
    mask = torch.cat(masks, dim=1) if len(masks) > 1 else masks[0]
    if scene.floor is None:
        floor = torch.zeros(batch, 2, dtype=dtype, device=rows.device)
    else:
        h = scene.floor.to(dtype).expand(batch)
        floor = torch.stack((torch.ones_like(h), h), dim=-1)
    if batch == 1 and scene.batch_shape == ():
        _ROWS.setdefault(scene, {})[key] = (rows, mask, floor)
    return rows, mask, floor


#: The rows of unbatched scenes at batch 1, kept while their scene lives (scenes are immutable).
_ROWS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


class ObstaclePathModel(nn.Module):
    """``forward(s0 (N, S), sT (N, S), rows, mask, floor) -> joints (N, C, T − 1, dof)``: the
    candidates' intermediate knots (not clamped). See the module docstring."""

    kind = "tm-obstacle-path"

    def __init__(self, config: ObstaclePathConfig):
        super().__init__()
        self.config = config
        self.layout = StateLayout(config.dof)
        dof = config.dof
        n_prim = PRIMITIVE_FEATURES[config.primitives]
        self.encoder = nn.Sequential(*mlp_layers((n_prim, *config.encoder), config.activation))
        n_in = self.n_problem_features + config.encoder[-1]
        out = nn.Linear(config.hidden[-1], config.candidates * config.modes * dof)
        gen = torch.Generator().manual_seed(0)
        with torch.no_grad():
            # Small weights, and each candidate a different fixed bend to start from: candidates that
            # start equal would stay equal under a winner-takes-all loss.
            out.weight.mul_(0.01)
            out.bias.copy_(0.15 * torch.randn(out.bias.shape, generator=gen))
            out.bias.view(config.candidates, config.modes, dof)[0].zero_()
        # The trunk's hidden layers are made after its output layer (the order the shipped model was
        # initialised in).
        self.trunk = nn.Sequential(*mlp_layers((n_in, *config.hidden), config.activation), out)
        register_path_buffers(self, config)
        self.register_buffer("in_mean", torch.zeros(self.n_problem_features))
        self.register_buffer("in_std", torch.ones(self.n_problem_features))
        self.register_buffer("prim_mean", torch.zeros(n_prim))
        self.register_buffer("prim_std", torch.ones(n_prim))
        #: The scene families it was trained on (names of :data:`kinlearn.data.problems.FAMILIES`),
        #: recorded by its trainer and kept in its checkpoint; None where none was recorded.
        self.families: tuple[str, ...] | None = None
        #: Whose paths its training also pulled a candidate towards (:mod:`kinlearn.training.obstacle_path`,
        #: distillation): ``"sampler"`` (the offline RRT-Connect's), ``"planner"`` (a planner's own plans),
        #: None (self-supervised alone); kept in its checkpoint.
        self.distilled: str | None = None
        #: The sphere set its training went through (``BodySpheres.name``: the ur5's ``"gripper"``), kept in
        #: its checkpoint; None where none was recorded (a learned body, or an older checkpoint).
        self.body: str | None = None

    @property
    def robot_name(self) -> str:
        return self.config.robot

    @property
    def row_columns(self) -> int:
        """How many of a primitive row's leading columns the encoder reads (``config.primitives``)."""
        return _COLUMNS[self.config.primitives]

    @property
    def n_problem_features(self) -> int:
        """[s(0), s(T), θ(T) − θ(0), has floor, floor height]."""
        return 2 * self.layout.size + self.config.dof + 2

    def problem_features(self, s0: torch.Tensor, sT: torch.Tensor, floor: torch.Tensor) -> torch.Tensor:
        J = self.layout.joints
        return torch.cat((s0, sT, sT[:, J] - s0[:, J], floor), dim=-1)

    def primitive_features(self, rows: torch.Tensor, s0: torch.Tensor, sT: torch.Tensor) -> torch.Tensor:
        E = self.layout.ef
        c = rows[..., :3]
        cols = rows[..., : self.row_columns]
        return torch.cat((cols, c - s0[:, None, E], c - sT[:, None, E]), dim=-1)

    @torch.no_grad()
    def fit_normalization(self, s0, sT, rows, mask, floor) -> None:
        """Standardise problem and primitive features with statistics of training problems."""
        x = self.problem_features(s0.double(), sT.double(), floor.double())
        self.in_mean.copy_(x.mean(0))
        self.in_std.copy_(x.std(0).clamp_min(MIN_STD))
        p = self.primitive_features(rows.double(), s0.double(), sT.double())[mask]
        self.prim_mean.copy_(p.mean(0))
        self.prim_std.copy_(p.std(0).clamp_min(MIN_STD))
        for k in _FLAGS[self.config.primitives]:  # the kind flags stay 0/1
            self.prim_mean[k], self.prim_std[k] = 0.0, 1.0

    @property
    def input_scales(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The standard deviations the problem and primitive features are divided by: ``in_std`` and
        ``prim_std``, infinite for a feature that never varied in training (its standard deviation at
        :data:`MIN_STD`), which is thereby held at its training mean whatever its value. Every
        training scene had a floor at z = 0: without this a scene with no floor (a MoveIt scene, a list of
        balls) put the floor flag 1,000 standard deviations from anything the network saw and its
        candidates were noise (the panda's cleared none of 120 problems with a ball across the path, and
        16% of its held-out scene problems with their floor left out, against 63% with it); held, the
        network plans as if the floor were at the base, and the dense check judges the scene as given.
        Likewise a primitive's tilt terms (``Lxz``, ``Lyz`` of its extent tensor) for a network trained
        without the clutter family, whose every box is turned about z alone: a tilted box is read through
        its bounding box and its other terms (the ur5's networks trained without clutter clear 100% of its
        held-out clutter problems in fixed time, 75% before)."""
        held = lambda s: torch.where(s > MIN_STD, s, torch.full_like(s, torch.inf))  # noqa: E731
        return held(self.in_std), held(self.prim_std)

    def scene_embedding(self, s0, sT, rows, mask) -> torch.Tensor:
        """``(N, encoder[-1])``: the masked max over the primitives' embeddings (zeros for no primitive)."""
        if rows.shape[1] == 0:
            return s0.new_zeros(s0.shape[0], self.config.encoder[-1])
        h = self.encoder((self.primitive_features(rows, s0, sT) - self.prim_mean) / self.input_scales[1])
        h = torch.where(mask[..., None], h, torch.full_like(h, -torch.inf)).amax(dim=1)
        return torch.where(torch.isfinite(h), h, torch.zeros_like(h))

    def coefficients(self, s0, sT, rows, mask, floor) -> torch.Tensor:
        """``(N, C, modes, dof)``: each candidate's sine-mode coefficients."""
        c = self.config
        x = (self.problem_features(s0, sT, floor) - self.in_mean) / self.input_scales[0]
        y = self.trunk(torch.cat((x, self.scene_embedding(s0, sT, rows, mask)), dim=-1))
        return y.view(-1, c.candidates, c.modes, c.dof)

    def forward(self, s0, sT, rows, mask, floor) -> torch.Tensor:
        J = self.layout.joints
        coef = self.coefficients(s0, sT, rows, mask, floor)
        theta0, thetaT = s0[:, None, None, J], sT[:, None, None, J]
        line = theta0 + self.fractions[:, None] * (thetaT - theta0)  # (N, 1, T − 1, dof)
        return line + self.half_range * (self.basis @ coef)


def save_obstacle_model(
    tm: ObstaclePathModel, path: str | Path, extra: dict | None = None, depends: dict | None = None
) -> Path:
    """Save an obstacle-aware TM: weights, its config, robot, the families it was trained on and format
    version (atomically)."""
    extra = {**(extra or {}), **_record(tm)}
    return save_checkpoint(
        path,
        kind=ObstaclePathModel.kind,
        robot=tm.robot_name,
        config=tm.config.to_dict(),
        state_dict=tm.state_dict(),
        extra=extra,
        depends=depends,
    )


def _record(tm: ObstaclePathModel) -> dict:
    """What a checkpoint keeps of how the model was trained."""
    extra: dict = {} if tm.families is None else {"families": list(tm.families)}
    if tm.distilled:  # the sampler's as True, as before a planner could teach
        extra["distilled"] = True if tm.distilled == "sampler" else tm.distilled
    if tm.body is not None:
        extra["body"] = tm.body
    return extra


def _families(payload: dict, path) -> tuple[str, ...] | None:
    families = payload["extra"].get("families")
    if families is None:
        return None
    if not isinstance(families, (list, tuple)) or not all(isinstance(f, str) for f in families):
        raise CheckpointError(f"{path}: its record of training families is not a list of names: {families!r}")
    return tuple(families)


def load_obstacle_model(path: str | Path, robot: str | None = None) -> ObstaclePathModel:
    """Load a model saved by :func:`save_obstacle_model` (training state, if any, is ignored)."""
    payload = load_checkpoint(path, kind=ObstaclePathModel.kind, robot=robot)
    try:
        tm = ObstaclePathModel(ObstaclePathConfig.from_dict(payload["config"]))
        tm.load_state_dict(payload["state_dict"])
    except (TypeError, KeyError, RuntimeError, ConfigError) as exc:
        raise CheckpointError(
            f"{path}: the obstacle TM checkpoint does not match this kinlearn ({exc})"
        ) from exc
    tm.families = _families(payload, path)
    distilled = payload["extra"].get("distilled", False)
    if distilled not in (False, True, "planner"):
        raise CheckpointError(f"{path}: its record of distillation is not one kinlearn knows: {distilled!r}")
    tm.distilled = "sampler" if distilled is True else (distilled or None)
    body = payload["extra"].get("body")
    if body is not None and not isinstance(body, str):
        raise CheckpointError(f"{path}: its record of the training body is not a name: {body!r}")
    tm.body = body
    return tm.eval()


def export_obstacle_model(src: str | Path, dst: str | Path, half: bool = True) -> Path:
    """Copy a trained model's weights and config from ``src`` to ``dst``, without its training state.

    ``half``: store the layers' weights as float16 (:func:`kinlearn.io.half_weights`: half the size;
    they load back into float32, changing the plans by rounding only). The exported file is what is judged: measure the exported planner."""
    payload = load_checkpoint(src, kind=ObstaclePathModel.kind)
    tm = load_obstacle_model(src)  # it must load
    state = half_weights(payload["state_dict"]) if half else payload["state_dict"]
    extra = _record(tm)
    return save_checkpoint(
        dst,
        kind=ObstaclePathModel.kind,
        robot=payload["robot"],
        config=payload["config"],
        state_dict=state,
        extra=extra,
    )
