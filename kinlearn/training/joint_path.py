"""Self-supervised training of the joint-path TM through a frozen forward model.

No planner teaches it. For each batch of problems (start and goal states drawn across the joint
range) the TM proposes the joints and end effector of every waypoint; the joint path between them
(refined so that no step exceeds the babbling step bound, the range the FM was trained on) is rolled
through the frozen FM (:meth:`~kinlearn.models.forward_inverse.ForwardModel.ef_along`), which says where the end
effector goes. The loss asks of that predicted end-effector path what a user asks of a plan:

- ``length``: its length, relative to the length of the straight joint line's path (predicted by the
  same FM, without gradient): the planner should move the hand less than joint interpolation;
- ``smoothness``: no sharp turns: the squared second difference of the end effector at the
  waypoints, relative to the straight joint line's length;
- ``spacing``: evenly spaced waypoints (the paper's spacing metrics);
- ``turn``: no turn of the end-effector path sharper than about 70°: consecutive segments whose
  directions' cosine falls below 0.3 are penalised by the square of the shortfall, both between
  waypoints and between the finer points the path is measured at;
- ``joint_smoothness``: the squared second difference of the joint waypoints (a small regulariser
  of the redundant joints, which the end effector does not see);
- ``limits``: joint waypoints outside the limits (the planner clamps them; this keeps it rare);
- ``rectification``: the end-effector head ê(t) against the FM's end effector at θ̂(t) (the paper's
  rectification term, here for the head that predicts it; the FM's side is not moved by it).

The goal state is reached by construction (the path ends at the goal's joints), so no term asks
for it. With the analytic FM (``fm="analytic"``) the same loss runs through the exact FK: the ablation.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import torch

from ..body.kinematics import kinematics
from ..body.robot import Robot, load_robot
from ..body.state import straight_line
from ..data.babbling import MAX_STEP
from ..data.endpoints import workspace_box
from ..errors import ConfigError, TrainingDivergedError
from ..models.forward_inverse import AnalyticFM, ForwardModel, load_fm
from ..models.joint_path import JointPathConfig, JointPathModel, densify, save_path_model
from .loop import iteration_loop, seed_everything

__all__ = ["PLANNER_MODEL", "PathLossConfig", "PathTrainConfig", "build_fm", "path_loss", "train_path_model"]


@dataclass(frozen=True)
class PathLossConfig:
    """Weights of the joint-path TM's loss terms (see the module docstring)."""

    length: float = 1.0
    smoothness: float = 0.05
    spacing: float = 0.1
    turn: float = 2.0
    joint_smoothness: float = 0.02
    limits: float = 10.0
    rectification: float = 10.0

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if not (v >= 0.0 and math.isfinite(v)):
                raise ConfigError(f"loss weight {f.name} must be a finite number ≥ 0, got {v}")


#: The joint-path TM that ``kinlearn train-planner`` trains by default (its ``--hidden`` and ``--modes``):
#: the shipped planners' widths, 128-128-128 (they were trained with ``--modes 8``). A bare
#: :class:`PathTrainConfig` (``model={}``: :class:`~kinlearn.models.joint_path.JointPathConfig`'s own
#: 256-256-256 and a free correction) is what ``reproduce``'s workspace task trains.
PLANNER_MODEL: dict = {"hidden": (128, 128, 128), "modes": 6}


@dataclass(frozen=True)
class PathTrainConfig:
    """Everything that decides a joint-path TM training run; saved as the run's ``config.json``.

    ``fm``: ``"learned"`` (``fm_checkpoint``, a path) or ``"analytic"`` (the ablation). Problems are
    drawn afresh every iteration, uniformly within ``range_fraction`` of the joint range (the
    ``workspace`` endpoint preset's distribution). ``max_step``: the babbling step bound (rad) the
    FM was trained on (its :attr:`~kinlearn.models.interface.ForwardModel.max_step`); the rolled-out
    path never steps further. Adam with cosine decay to zero.
    """

    robot: str = "iiwa14"
    fm: Literal["learned", "analytic"] = "learned"
    fm_checkpoint: str | None = None
    iterations: int = 6000
    batch_size: int = 512
    lr: float = 2e-3
    range_fraction: float = 1.0
    max_step: float = MAX_STEP
    checkpoint_every: int = 250
    loss: PathLossConfig = field(default_factory=PathLossConfig)
    model: dict = field(default_factory=dict)
    seed: int = 0

    def __post_init__(self) -> None:
        if self.fm not in ("learned", "analytic"):
            raise ConfigError(f"fm must be 'learned' or 'analytic', got {self.fm!r}")
        if self.fm == "learned" and not self.fm_checkpoint:
            raise ConfigError("a learned FM needs fm_checkpoint, the path of its fm.pt")
        for name in ("iterations", "batch_size", "checkpoint_every"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ConfigError(f"{name} must be a positive integer, got {v!r}")
        if not (self.lr > 0.0 and math.isfinite(self.lr)):
            raise ConfigError(f"lr must be a positive finite number, got {self.lr}")
        if not (self.max_step > 0.0 and math.isfinite(self.max_step)):
            raise ConfigError(f"max_step must be a positive number of radians, got {self.max_step}")
        if not 0.0 < self.range_fraction <= 1.0:
            raise ConfigError(f"range_fraction must lie in (0, 1], got {self.range_fraction}")

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> PathTrainConfig:
        d = dict(d)
        d["loss"] = PathLossConfig(**d.get("loss", {}))
        return cls(**d)

    def model_config(self, robot: Robot) -> JointPathConfig:
        return JointPathConfig.for_robot(robot, **self.model)


#: Points per waypoint segment at which the loss measures the end-effector path.
LENGTH_POINTS = 3
#: Consecutive end-effector segments whose directions' cosine falls below this are penalised (≈ 72°).
TURN_COSINE = 0.3


def _turns(d: torch.Tensor) -> torch.Tensor:
    """Mean over a batch of the summed squared shortfall of consecutive segments' cosine below
    :data:`TURN_COSINE`; ``d``: ``(N, K, 3)`` segments."""
    cos = (d[:, 1:] * d[:, :-1]).sum(-1) / (d[:, 1:].norm(dim=-1) * d[:, :-1].norm(dim=-1) + 1e-4)
    return torch.relu(TURN_COSINE - cos).square().sum(-1).mean()


def _path_length(ef: torch.Tensor) -> torch.Tensor:
    return (ef[:, 1:] - ef[:, :-1]).norm(dim=-1).sum(-1)


def path_loss(
    tm: JointPathModel,
    fm: ForwardModel,
    s0: torch.Tensor,
    sT: torch.Tensor,
    config: PathLossConfig,
    max_step: float,
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """The configured loss of ``tm`` on problems ``(s0, sT)`` through the frozen ``fm``, and its terms."""
    J, E = tm.layout.joints, tm.layout.ef
    out = tm(s0, sT)
    theta0, thetaT, ef0 = s0[:, J], sT[:, J], s0[:, E]
    knots = torch.cat((theta0[:, None], out.joints, thetaT[:, None]), dim=1)
    # A diverged model's paths leave every joint range (or turn NaN); densifying them would try to
    # allocate without bound. The training loop's own check sees the loss only after this.
    step = float((knots[:, 1:] - knots[:, :-1]).detach().abs().amax()) if knots.numel() else 0.0
    if not (step <= 20 * float(tm.half_range.max())):
        raise TrainingDivergedError(
            f"joint-path TM training diverged (its paths step {step:.3g} rad between knots, beyond 10× the "
            "joint range); lower the learning rate"
        )
    dense, m = densify(knots, max_step, multiple_of=LENGTH_POINTS)
    every = m // LENGTH_POINTS  # the path is measured at LENGTH_POINTS points per segment
    ef = fm.ef_along(dense, ef0, every)
    with torch.no_grad():
        ref = _path_length(fm.ef_along(straight_line(theta0, thetaT, dense.shape[1] - 1), ef0, every))
    scale = ref + 0.02  # metres: keeps near-zero moves from dominating
    length = (_path_length(ef) / scale).mean()
    ef_k = ef[:, ::LENGTH_POINTS]  # the end effector at the waypoints (K + 1 points)
    T = knots.shape[1] - 1
    accel = ef_k[:, 2:] - 2 * ef_k[:, 1:-1] + ef_k[:, :-2]
    smooth = (accel.square().sum((-1, -2)) * T**2 / scale.square()).mean()
    seg = (ef_k[:, 1:] - ef_k[:, :-1]).norm(dim=-1)
    # Relative to the spacing of an even path: a slow-down (where a path tends to kink) costs as much on
    # a short move as on a long one.
    spacing = ((seg - seg.mean(-1, keepdim=True)).square().mean(-1) / (scale / T).square()).mean()
    # Turns at the waypoints (where the metrics look) and between them (finer, so no corner hides there).
    turn = _turns(ef_k[:, 1:] - ef_k[:, :-1]) + _turns(ef[:, 1:] - ef[:, :-1])
    jacc = knots[:, 2:] - 2 * knots[:, 1:-1] + knots[:, :-2]
    joint_smooth = jacc.square().sum((-1, -2)).mean()
    limits = (
        (torch.relu(out.joints - tm.upper) + torch.relu(tm.lower - out.joints)).square().sum((-1, -2)).mean()
    )
    rect = (out.ef - ef_k[:, 1:-1].detach()).square().sum(-1).mean()
    c = config
    loss = (
        c.length * length
        + c.smoothness * smooth
        + c.spacing * spacing
        + c.turn * turn
        + c.joint_smoothness * joint_smooth
        + c.limits * limits
        + c.rectification * rect
    )
    terms = {
        "length_ratio": length.detach(),
        "smoothness": smooth.detach(),
        "spacing": spacing.detach(),
        "turn": turn.detach(),
        "joint_smoothness": joint_smooth.detach(),
        "limits": limits.detach(),
        "rectification": rect.detach(),
        "substeps": torch.tensor(float(m)),
    }
    return loss, terms


def _sample_problems(
    robot: Robot, lo, hi, n: int, gen: torch.Generator, kin
) -> tuple[torch.Tensor, torch.Tensor]:
    q = lo + (hi - lo) * torch.rand(2, n, robot.dof, generator=gen, dtype=torch.float64)
    ef = kin.position(q, validate=False)
    s = torch.cat((q, ef), dim=-1).float()
    return s[0], s[1]


def build_fm(config: PathTrainConfig, robot: Robot) -> ForwardModel:
    """The frozen FM that ``config`` names."""
    fm = AnalyticFM(robot) if config.fm == "analytic" else load_fm(config.fm_checkpoint, robot=robot.name)
    fm.eval().requires_grad_(False)
    fm.validate_inputs = False
    return fm


def train_path_model(
    config: PathTrainConfig,
    run_dir: str | Path,
    *,
    fm: ForwardModel | None = None,
    resume: bool = True,
    progress: bool = True,
    write_config: bool = True,
    depends: dict | None = None,
) -> JointPathModel:
    """Train a joint-path TM; checkpoint ``run_dir/tm.pt`` every ``checkpoint_every`` iterations and at
    the end (atomically), and resume from it. Logs the loss terms to ``run_dir/metrics.jsonl``.
    ``write_config=False`` leaves ``run_dir/config.json`` to the caller (the CLI keeps its run record there).
    ``depends``: the ``fm.pt``/``im.pt`` a planner folder holds beside the TM, recorded in its checkpoint."""
    run_dir = Path(run_dir)
    robot = load_robot(config.robot)
    fm = fm if fm is not None else build_fm(config, robot)
    if fm.robot_name != robot.name:
        raise ConfigError(f"the FM is for {fm.robot_name!r}, the run is for {robot.name!r}")
    gen = seed_everything(config.seed)
    tm = JointPathModel(config.model_config(robot))
    kin = kinematics(robot)
    lo, hi = workspace_box(robot, config.range_fraction)
    # Normalisation statistics from a fixed sample of the training distribution.
    s0, sT = _sample_problems(robot, lo, hi, 65536, torch.Generator().manual_seed(config.seed + 1), kin)
    S = tm.layout.size
    box_lo = torch.full((2 * S,), -torch.inf, dtype=torch.float64)
    box_hi = torch.full((2 * S,), torch.inf, dtype=torch.float64)
    for k in (0, S):  # the joints of start and goal; the end effector follows from them
        box_lo[k : k + robot.dof], box_hi[k : k + robot.dof] = lo, hi
    tm.fit_normalization(s0, sT, domain=(box_lo, box_hi))
    loop = iteration_loop(
        tm,
        config,
        run_dir,
        "tm.pt",
        lambda path, extra: save_path_model(tm, path, depends=depends, extra=extra),
        kind=JointPathModel.kind,
        robot=robot.name,
        generator=gen,
        resume=resume,
        write_config=write_config,
        desc="joint-path TM training",
        progress=progress,
        postfix=("train/loss", "train/length_ratio"),
    )

    def step(_: int) -> dict[str, float]:
        s0, sT = _sample_problems(robot, lo, hi, config.batch_size, gen, kin)
        loss, terms = path_loss(tm, fm, s0, sT, config.loss, config.max_step)
        return {
            "train/loss": float(loop.step(loss, check=True)),
            **{f"train/{k}": v for k, v in terms.items()},
        }

    loop.run(step)
    return tm
