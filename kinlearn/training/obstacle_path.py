"""Self-supervised training of the obstacle-aware TM through a frozen body model.

No planner shows it a path. Each iteration draws training problems (start and goal joints in a
scene, from :func:`~kinlearn.data.problems.make_problems` with seeds other than the benchmark's,
unverified: nothing needs to know a path exists), and the TM proposes ``candidates`` joint paths for
each. Every candidate is cut into ``points`` configurations per segment and put through the frozen
body model (the analytic sphere body, or the one the robot learned from babbling), which says where
the arm's spheres are. A candidate's loss asks what a user asks of a plan around obstacles:

- ``collision``: the hinge ``max(0, margin − d)`` of every body sphere's signed distance ``d`` to the
  scene (floor included), summed over spheres and averaged over the configurations;
- ``self_collision``: the same hinge over the body's self-collision sphere pairs;
- ``length``: the distance the body's spheres travel along the path, relative to how far they travel
  along the straight joint line (so the arm moves no more than it must);
- ``joint_smoothness``: the squared second difference of the knots (no joint-space kinks);
- ``limits``: knots outside the joint limits (the planner clamps them; this keeps it rare).

The problem's loss is the best candidate's plus ``spread`` times the candidates' mean
(winner-takes-all, relaxed so no candidate is abandoned): the candidates learn different ways
around, and the planner keeps whichever its check finds free. Resumable bit-identically, like the
other trainers.

Distillation (an option, off by default: ``ObstacleLossConfig.imitation`` > 0). The compiled
RRT-Connect solves each training problem once, offline (:func:`expert_paths`: a fixed iteration
budget, so the same paths on every machine; cached beside the problems), and its shortcut path,
resampled to the model's knots by arc length, is a target: the candidate nearest to it (in joint
ranges) is pulled towards it by ``imitation`` times the mean squared knot difference, on top of the
self-supervised loss every candidate keeps. The sampler shows the way out of a cell; the body's
hinges still decide what is free. A network trained so is marked as distilled in its checkpoint.
Self-distillation (``ObstacleTrainConfig.teacher="planner"``) takes a kinlearn planner's own plans as
the targets instead (its retreat stage's paths and, where its fixed-time stages clear nothing, its
sampler's), written beforehand by :func:`kinlearn.planning.teacher.planner_paths`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import torch

from ..body.kinematics import kinematics
from ..body.robot import Robot, load_robot
from ..checks import as_real
from ..collision.body import BodySpheres, body_spheres
from ..collision.distance import body_obstacle_distance, self_collision_distance
from ..collision.geometry import safe_sqrt
from ..data.problems import FAMILIES, LEGACY_FAMILIES, ProblemConfig, ProblemSet, make_problems
from ..data.target_paths import TEACHERS, load_target_paths, read_target_paths, save_target_paths
from ..errors import ConfigError, DatasetError
from ..models.obstacle_path import (
    ObstaclePathConfig,
    ObstaclePathModel,
    load_obstacle_model,
    save_obstacle_model,
    scene_primitives,
)
from ..polyline import resample
from .loop import iteration_loop, seed_everything

__all__ = [
    "TRAINING_SEEDS",
    "ObstacleLossConfig",
    "ObstacleTrainConfig",
    "build_body",
    "candidate_losses",
    "expert_paths",
    "make_training_problems",
    "planner_paths",
    "train_obstacle_model",
]

#: Seeds of the training problems, one per family (the held-out benchmark sets use 1001–1010).
TRAINING_SEEDS = {name: 2001 + k for k, name in enumerate(FAMILIES)}  # tabletop 2001, shelf 2002, …


@dataclass(frozen=True)
class ObstacleLossConfig:
    """Weights and margins of the obstacle-aware TM's loss (see the module docstring)."""

    collision: float = 1000.0
    self_collision: float = 1000.0
    margin: float = 0.03  # m
    length: float = 1.0
    joint_smoothness: float = 0.05
    limits: float = 10.0
    spread: float = 0.05
    imitation: float = 0.0  # > 0: distil the compiled RRT-Connect's paths (see the module docstring)

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            v = as_real(v, f"ObstacleLossConfig.{f.name}", minimum=0.0, expected="a finite number ≥ 0")
            object.__setattr__(self, f.name, v)


@dataclass(frozen=True)
class ObstacleTrainConfig:
    """Everything that decides an obstacle-aware TM training run; saved as the run's ``config.json``.

    ``problems``: ``.npz`` problem sets (:meth:`ProblemSet.save`) to train on, e.g. from
    :func:`make_training_problems`. ``body``: ``"analytic"`` (the sphere model) or ``"learned"``
    (``body_checkpoint``, a learned body model). ``points``: configurations per segment at which the
    loss looks at the body. ``init_checkpoint``: start from a trained model's weights and input
    standardisation (fine-tuning, e.g. on more problems) instead of a fresh one; its architecture must
    match ``model``. ``solvable_only``: train on the problems the compiled RRT-Connect solves within
    :data:`EXPERT_ITERATIONS` (:func:`expert_paths`, made once and cached) and drop the rest: unverified
    problems include infeasible ones (start and goal in parts of the free space that do not connect),
    whose loss can only pull paths through obstacles. A filter, not a teacher: no path is shown unless
    ``loss.imitation`` > 0. ``teacher``: whose paths the filter and the imitation read (see
    :mod:`kinlearn.data.target_paths`): ``"sampler"`` (the compiled RRT-Connect, made here when
    missing) or ``"planner"`` (a kinlearn planner's own plans, self-distillation: made beforehand by
    :func:`kinlearn.planning.teacher.planner_paths`). Adam with cosine decay to zero.
    """

    robot: str = "iiwa14"
    problems: tuple[str, ...] = ()
    body: Literal["analytic", "learned"] = "analytic"
    body_checkpoint: str | None = None
    iterations: int = 3000
    batch_size: int = 64
    lr: float = 2e-3
    points: int = 2
    checkpoint_every: int = 100
    init_checkpoint: str | None = None
    solvable_only: bool = False
    teacher: Literal["sampler", "planner"] = "sampler"
    loss: ObstacleLossConfig = field(default_factory=ObstacleLossConfig)
    model: dict = field(default_factory=dict)
    seed: int = 0

    def __post_init__(self) -> None:
        if not self.problems:
            raise ConfigError("ObstacleTrainConfig.problems must name at least one problem set (.npz)")
        if self.teacher not in TEACHERS:
            raise ConfigError(f"teacher must be one of {', '.join(TEACHERS)}, got {self.teacher!r}")
        if self.body not in ("analytic", "learned"):
            raise ConfigError(f"body must be 'analytic' or 'learned', got {self.body!r}")
        if self.body == "learned" and not self.body_checkpoint:
            raise ConfigError("a learned body needs body_checkpoint, the path of its body.pt")
        for name in ("iterations", "batch_size", "points", "checkpoint_every"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ConfigError(f"{name} must be a positive integer, got {v!r}")
        if not (self.lr > 0.0 and math.isfinite(self.lr)):
            raise ConfigError(f"lr must be a positive finite number, got {self.lr}")

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["problems"] = list(self.problems)
        if not self.loss.imitation:  # a self-supervised run's record, as before distillation existed
            del d["loss"]["imitation"]
        if not self.solvable_only:  # and as before the filter existed
            del d["solvable_only"]
        if self.teacher == "sampler":  # and as before a planner could teach
            del d["teacher"]
        return d

    @classmethod
    def from_dict(cls, d: dict) -> ObstacleTrainConfig:
        d = dict(d)
        d["loss"] = ObstacleLossConfig(**d.get("loss", {}))
        d["problems"] = tuple(d.get("problems", ()))
        return cls(**d)

    def model_config(self, robot: Robot) -> ObstaclePathConfig:
        return ObstaclePathConfig.for_robot(robot, **self.model)


def make_training_problems(
    out_dir: str | Path,
    per_family: int,
    chunk: int = 250,
    robot: Robot | None = None,
    progress=None,
    families: tuple[str, ...] = LEGACY_FAMILIES,
    sphere_set: str | None = None,
    within: str = "robot",
    max_attempts: int | None = None,
) -> list[Path]:
    """Generate (or reuse) unverified training problems: ``per_family`` of each of ``families`` (default
    the three the shipped iiwa14 network was trained on) with :data:`TRAINING_SEEDS`, in files of
    ``chunk`` problems under ``out_dir``, for the body ``sphere_set`` names (default the robot's planning
    body, :class:`~kinlearn.data.problems.ProblemConfig`), starts and goals within the joint limits
    ``within`` names (``"robot"`` or ``"body"``: the body's, the ur5's tool model's ±π). Deterministic:
    chunk c of a family is problems ``c·chunk …`` of its seed's sequence, whoever generates it.
    ``max_attempts``: scenes tried per problem (default :class:`~kinlearn.data.problems.ProblemConfig`'s). A file
    already there made for another body or within other limits is a :class:`~kinlearn.errors.ConfigError`
    (choose another ``out_dir``)."""
    unknown = [f for f in families if f not in FAMILIES]
    if not families or unknown:
        raise ConfigError(f"training families must be some of {', '.join(FAMILIES)}, got {list(families)}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    # a small arm's cells hold fewer free poses: more scenes tried per problem
    extra = {} if max_attempts is None else {"max_attempts": max_attempts}
    cfg = ProblemConfig(verify=False, sphere_set=sphere_set, within=within, **extra)
    robot = robot or load_robot("iiwa14")
    want = cfg.body(robot).name
    paths = []
    for c in range(math.ceil(per_family / chunk)):
        n = min(chunk, per_family - c * chunk)
        for fam in families:
            path = out_dir / (f"{fam}_{c:02d}.npz" if n == chunk else f"{fam}_{c:02d}_{n}.npz")
            if not path.is_file():
                make_problems(fam, n, TRAINING_SEEDS[fam], robot=robot, config=cfg, first=c * chunk).save(
                    path
                )
            else:
                held = ProblemSet.load(path, robot=robot.name)
                held_body = held.body(robot).name
                if held_body != want:
                    raise ConfigError(f"{path} holds problems made for the {held_body!r} body, not {want!r}")
                if held.within != within:
                    raise ConfigError(
                        f"{path} holds problems made within the {held.within}'s limits, not the {within}'s"
                    )
            paths.append(path)
            if progress is not None:
                progress(len(paths))
    return paths


#: The offline sampler's iteration budget per training problem (a budget of work: the same paths on
#: every machine); a problem it leaves unsolved has no target.
EXPERT_ITERATIONS = 20000


def expert_paths(
    problems: str | Path, robot: Robot, knots: int, progress=None
) -> tuple[torch.Tensor, torch.Tensor]:
    """The compiled RRT-Connect's path of every problem of the set in ``problems`` (``.npz``), its vertices
    skipped where a straight segment is free (no partial shortcuts: a target hugging the obstacles'
    corners pulls against the clearance the loss asks for) and resampled to ``knots + 1`` points by arc
    length: ``(paths (N, knots + 1, dof) float64, found (N,)
    bool)``. Each problem gets :data:`EXPERT_ITERATIONS` iterations with its index as the seed (no time
    limit: the same paths everywhere), searching the problem's joint box as the planner does
    (:meth:`~kinlearn.collision.BodySpheres.joint_box`). Made once and cached beside the set (the
    ``sampler`` teacher's file of :mod:`kinlearn.data.target_paths`, written atomically); a cache of
    another set, robot or size is made again."""
    from ..collision import kernel
    from ..collision.rrt import rrt_connect

    pset = ProblemSet.load(problems, robot=robot.name)
    body = pset.body(robot).double()
    want = {
        "problems": Path(problems).name,
        "knots": knots,
        "iterations": EXPERT_ITERATIONS,
        "n": len(pset),
        "body": body.name,
        "box": "joint_box",
    }
    held = load_target_paths(problems, robot.name, "sampler", knots, want)
    if held is not None:
        return torch.from_numpy(held[0]), torch.from_numpy(held[1])
    lo, hi = body.joint_box(pset.start.numpy(), pset.goal.numpy())
    body = kernel.KernelBody.of(body)
    paths = np.zeros((len(pset), knots + 1, robot.dof))
    found = np.zeros(len(pset), dtype=bool)
    for i in range(len(pset)):
        start, goal, scene = pset.problem(i)
        path, _, _ = rrt_connect(
            body, kernel.KernelScene.of(scene.to(torch.float64)), start.double().numpy(), goal.double().numpy(),
            lo[i], hi[i], time_limit=math.inf, seed=i, max_iterations=EXPERT_ITERATIONS,
            shortcut_attempts=0,
        )  # fmt: skip
        if path is not None:
            paths[i], found[i] = resample(path, knots + 1), True
        if progress is not None:
            progress(i + 1)
    save_target_paths(problems, robot.name, "sampler", knots, want, paths, found)
    return torch.from_numpy(paths), torch.from_numpy(found)


def planner_paths(problems: str | Path, robot: Robot, knots: int) -> tuple[torch.Tensor, torch.Tensor]:
    """A planner's own plans of the set in ``problems`` as ``(paths (N, knots + 1, dof) float64, found
    (N,) bool)``: the ``planner`` teacher's file beside the set (:mod:`kinlearn.data.target_paths`), made
    beforehand by :func:`kinlearn.planning.teacher.planner_paths` (``kinlearn train-obstacle-planner
    --teacher planner`` makes it). A :class:`~kinlearn.errors.ConfigError` where there is none for
    this set, robot and number of knots."""
    n = len(ProblemSet.load(problems, robot=robot.name))
    try:
        _, paths, found = read_target_paths(problems, robot.name, "planner", knots, n)
    except DatasetError as exc:
        raise ConfigError(
            f"teacher 'planner' needs a planner's paths of {problems} at {knots} knots "
            f"(make them with kinlearn.planning.teacher.planner_paths): {exc}"
        ) from exc
    return torch.from_numpy(paths), torch.from_numpy(found)


def build_body(config: ObstacleTrainConfig, robot: Robot, problems: ProblemSet | None = None):
    """The frozen body model ``config`` names, in float32: the analytic one is the sphere set the
    training ``problems`` were made for (:meth:`ProblemSet.body`; without them the robot's default)."""
    if config.body == "analytic":
        body = problems.body(robot) if problems is not None else body_spheres(robot)
    else:
        from ..models.body import load_body_model

        body = load_body_model(config.body_checkpoint, robot=robot.name)
    return body.float().eval().requires_grad_(False)


def _dense(knots: torch.Tensor, fractions: torch.Tensor) -> torch.Tensor:
    """``(..., K + 1, dof)`` → ``(..., K·P + 1, dof)``: each segment at ``fractions (P,)`` of the way
    (in [0, 1)), then the last knot."""
    f = fractions.to(knots)[:, None]
    seg = knots[..., :-1, None, :] + f * (knots[..., 1:, None, :] - knots[..., :-1, None, :])
    return torch.cat((seg.flatten(-3, -2), knots[..., -1:, :]), dim=-2)


def _travel(centres: torch.Tensor, moving: torch.Tensor) -> torch.Tensor:
    """``(..., Q, M, 3)`` → ``(...)``: the distance the moving spheres travel, summed."""
    step = (centres[..., 1:, :, :] - centres[..., :-1, :, :]).norm(dim=-1)
    return (step * moving).sum((-1, -2))


def _scene_clearance(centres: torch.Tensor, radii: torch.Tensor, scene, floor_mask) -> torch.Tensor:
    """``centres (N, R, M, 3)`` → ``(N, R, M)``: each sphere's signed distance to its problem's scene
    (batch ``(N,)``, floor included): the distances of :mod:`kinlearn.collision.distance`."""
    _, per = body_obstacle_distance(
        centres, radii, scene.unsqueeze(-1), per_sphere=True, floor_mask=floor_mask
    )
    return per


#: Metres added to the margin where the compiled kernel (float64) picks the spheres and configurations
#: worth measuring again in float32: far above the two's rounding, so nothing with a gradient is missed,
#: and what is picked beyond the margin adds a hinge of exactly 0.
_PICK_SLACK = 1e-4


def _near_spheres(body, dense, scene, arm, margin):
    """Which spheres come within ``margin`` of their problem's scene, and which configurations within
    ``margin`` of self-collision: ``(near (N, R, M_arm) bool, self_near (N, R) bool)`` for
    configurations ``dense (N, R, dof)``. Found without a graph: by the compiled kernel, one call per
    problem, for the analytic sphere body; by torch for a learned body."""
    from ..collision import kernel

    if type(body) is BodySpheres:
        kb = kernel.KernelBody.of(body)
        q = dense.detach().double().numpy()
        near = torch.empty((*dense.shape[:2], int(arm.sum())), dtype=torch.bool)
        self_near = torch.empty(dense.shape[:2], dtype=torch.bool)
        cut, moving = margin + _PICK_SLACK, arm.numpy()
        for i in range(q.shape[0]):
            _, s, per = kernel.clearances(kb, kernel.KernelScene(scene[i]), q[i], per_sphere=True)
            near[i] = torch.from_numpy(per[:, moving] < cut)
            self_near[i] = torch.from_numpy(s < cut)
        return near, self_near
    with torch.no_grad():
        centres = body(dense, validate=False)
        radii = body.radii_like(centres)
        near = _scene_clearance(centres[..., arm, :], radii[arm], scene, body.floor_mask[arm]) < margin
        _, per = self_collision_distance(centres, radii, body.pairs, per_pair=True)
        return near, (per < margin).any(-1)


def _scene_hinge(centres: torch.Tensor, radii: torch.Tensor, scene, floor_mask, near) -> tuple:
    """For ``centres (N, R, M, 3)``, the signed distance ``d (A,)`` to its problem's scene (batch
    ``(N,)``) of each sphere ``near (N, R, M)`` picks (:func:`_near_spheres`; the others' hinges are 0,
    with no gradient), with its problem and configuration indices: ``(n, r, d)``, the hinge
    ``max(0, margin − d)`` left to the caller. A sphere's signed distance is its centre's distance less
    its radius (the floor's too), so they are measured as points."""
    n, r, m = near.nonzero(as_tuple=True)
    d = centres.new_empty(n.shape)
    fm = floor_mask[m]
    zero = radii.new_zeros(1)
    for applies in (True, False):  # the floor applies to a sphere or not: one call for each kind
        pick = fm == applies
        if bool(pick.any()):
            c = centres[n[pick], r[pick], m[pick]].unsqueeze(-2)  # (A, 1, 3): each a one-point body
            _, per = body_obstacle_distance(
                c, zero, scene[n[pick]], per_sphere=True, floor_mask=torch.tensor([applies])
            )
            d[pick] = per[:, 0] - radii[m[pick]]
    return n, r, d


def _self_gaps(centres: torch.Tensor, radii: torch.Tensor, pairs: torch.Tensor, near, margin: float):
    """The gaps ``(A,)`` of the sphere pairs within ``margin`` in the configurations ``near (...)`` picks
    (the others are farther than the margin from self-collision), and their flat configuration indices
    ``(A,)``: the pairs are found by the compiled broad phase without a graph
    (:func:`~kinlearn.collision.kernel.near_pairs`), then measured again with one."""
    from ..collision.kernel import near_pairs

    flat = centres.reshape(-1, *centres.shape[-2:])
    b = near.reshape(-1).nonzero(as_tuple=True)[0]
    a, k = near_pairs(flat[b].detach().numpy(), radii.numpy(), pairs.numpy(), margin + _PICK_SLACK)
    b, i, j = b[torch.from_numpy(a)], pairs[torch.from_numpy(k), 0], pairs[torch.from_numpy(k), 1]
    return b, safe_sqrt((flat[b, i] - flat[b, j]).square().sum(-1)) - radii[i] - radii[j]


def candidate_losses(
    tm: ObstaclePathModel,
    body: BodySpheres,
    s0: torch.Tensor,
    sT: torch.Tensor,
    scene,
    config: ObstacleLossConfig,
    fractions: torch.Tensor,
    expert: torch.Tensor | None = None,
    box: tuple[torch.Tensor, torch.Tensor] | None = None,
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Each candidate's loss ``(N, C)`` for problems ``(s0, sT)`` in ``scene`` (batch ``(N,)``), and the
    terms (per candidate, not reduced). The body is looked at in every segment at ``fractions`` (in
    [0, 1)) of the way, and at the goal. ``expert`` ``(N, T − 1, dof)``: target inner knots; its term
    ``imitation`` (each candidate's mean squared knot difference, in half joint ranges) is returned
    with the terms and not added to the loss (the caller takes its minimum over the candidates).
    ``box``: each problem's joint box ``(lower, upper)``, each ``(N, dof)``, that its knots are clamped
    to and its ``limits`` term measures against, as the planner keeps a problem's paths in it
    (:meth:`~kinlearn.collision.BodySpheres.joint_box`); default the model's joint limits."""
    J = tm.layout.joints
    n = s0.shape[0]
    rows, mask, floor = scene_primitives(scene, n, s0.dtype)
    mid = tm(s0, sT, rows, mask, floor)  # (N, C, T − 1, dof)
    C = mid.shape[1]
    theta0 = s0[:, None, None, J].expand(n, C, 1, -1)
    thetaT = sT[:, None, None, J].expand(n, C, 1, -1)
    if box is None:
        lo, hi = tm.lower, tm.upper
    else:
        lo, hi = (b.to(mid)[:, None, None, :] for b in box)
    knots = torch.cat((theta0, mid.clamp(lo, hi), thetaT), dim=2)  # (N, C, T + 1, dof)
    dense = _dense(knots, fractions)  # (N, C, Q, dof)
    Q = dense.shape[2]
    centres = body(dense, validate=False)  # (N, C, Q, M, 3)
    radii = body.radii_like(centres)
    # The base's spheres never move: a path cannot change their clearance, so only the arm's count.
    arm = body.link > 0
    # The hinges below are 0, with no gradient, for spheres farther than the margin from the scene
    # and configurations farther from self-collision: those are found first without a graph, and
    # only the rest are measured with one (the same loss and gradient, a fraction of the work).
    near, self_near = _near_spheres(body, dense.flatten(1, 2), scene, arm, config.margin)
    pn, pr, d = _scene_hinge(
        centres[..., arm, :].flatten(1, 2), radii[arm], scene, body.floor_mask[arm], near
    )
    hinge = centres.new_zeros(n, C * Q).index_put((pn, pr), torch.relu(config.margin - d), accumulate=True)
    collision = hinge.view(n, C, Q).mean(-1)  # (N, C)
    b, gap = _self_gaps(centres, radii, body.pairs, self_near, config.margin)
    per_config = centres.new_zeros(n * C * Q).index_add(0, b, torch.relu(config.margin - gap))
    self_col = per_config.view(n, C, Q).mean(-1)  # (N, C)
    moving = (body.link > 0).to(centres.dtype)
    with torch.no_grad():
        steps = torch.arange(4 * (knots.shape[2] - 1), dtype=s0.dtype) / (4 * (knots.shape[2] - 1))
        line = _dense(torch.cat((theta0[:, :1], thetaT[:, :1]), dim=2), steps)
        ref = _travel(body(line, validate=False), moving)  # (N, 1)
    length = _travel(centres, moving) / (ref + 0.05)
    jacc = knots[:, :, 2:] - 2 * knots[:, :, 1:-1] + knots[:, :, :-2]
    joint_smooth = jacc.square().sum((-1, -2))
    limits = (torch.relu(mid - hi) + torch.relu(lo - mid)).square().sum((-1, -2))
    c = config
    loss = (
        c.collision * collision
        + c.self_collision * self_col
        + c.length * length
        + c.joint_smoothness * joint_smooth
        + c.limits * limits
    )
    terms = {
        "collision": collision,
        "self_collision": self_col,
        "length_ratio": length,
        "joint_smoothness": joint_smooth,
        "limits": limits,
    }
    if expert is not None:
        terms["imitation"] = ((mid - expert[:, None]) / tm.half_range).square().mean((-1, -2))
    return loss, terms


def _load_pool(paths, robot: Robot) -> ProblemSet:
    sets = [ProblemSet.load(p, robot=robot.name) for p in paths]
    return sets[0] if len(sets) == 1 else ProblemSet.concat(sets)


def _batch(pool, ef_all, idx, swap):
    """Problems ``idx`` of the pool as float32 states and scene, start and goal swapped where ``swap``."""
    q0, q1 = pool.start[idx], pool.goal[idx]
    e0, e1 = ef_all[0][idx], ef_all[1][idx]
    w = swap[:, None]
    s0 = torch.cat((torch.where(w, q1, q0), torch.where(w, e1, e0)), -1).float()
    sT = torch.cat((torch.where(w, q0, q1), torch.where(w, e0, e1)), -1).float()
    return s0, sT, pool.scene[idx].to(dtype=torch.float32)


def train_obstacle_model(
    config: ObstacleTrainConfig,
    run_dir: str | Path,
    *,
    resume: bool = True,
    progress: bool = True,
    write_config: bool = True,
) -> ObstaclePathModel:
    """Train an obstacle-aware TM; checkpoint ``run_dir/tm_obstacles.pt`` every ``checkpoint_every``
    iterations and at the end (atomically), and resume from it. Logs to ``run_dir/metrics.jsonl``."""
    run_dir = Path(run_dir)
    robot = load_robot(config.robot)
    pool = _load_pool(config.problems, robot)
    body = build_body(config, robot, pool)
    gen = seed_everything(config.seed)
    tm = ObstaclePathModel(config.model_config(robot))
    kin = kinematics(robot)
    experts = found = None
    if config.loss.imitation > 0 or config.solvable_only:  # the offline sampler's paths, in the pool's order
        targets = expert_paths if config.teacher == "sampler" else planner_paths
        parts = [targets(p, robot, tm.config.steps) for p in config.problems]
        experts = torch.cat([e for e, _ in parts])[:, 1:-1].float()
        found = torch.cat([f for _, f in parts])
        if config.solvable_only:
            if not bool(found.any()):
                raise ConfigError("solvable_only: the sampler solved none of the training problems")
            pool, experts, found = pool[found], experts[found], found[found]
    ef_all = (kin.position(pool.start), kin.position(pool.goal))
    # Each problem's joint box, as the planner searches it (the same either way round).
    box_all = tuple(
        torch.from_numpy(b) for b in pool.body(robot).joint_box(pool.start.numpy(), pool.goal.numpy())
    )
    n_pool = len(pool)
    seen = {f for i, f in enumerate(FAMILIES) if bool((pool.family == i).any())}
    if config.init_checkpoint:
        init = load_obstacle_model(config.init_checkpoint, robot=robot.name)
        if init.config.to_dict() != tm.config.to_dict():
            raise ConfigError(
                f"init_checkpoint {config.init_checkpoint} has another architecture than the run's model"
            )
        tm.load_state_dict(init.state_dict())
        seen |= set(init.families or ())
    else:  # standardise with both directions, as training draws them
        rows_all, mask_all, floor_all = scene_primitives(pool.scene, n_pool, torch.float64)
        s0_all = torch.cat((pool.start, ef_all[0]), -1)
        sT_all = torch.cat((pool.goal, ef_all[1]), -1)
        tm.fit_normalization(
            torch.cat((s0_all, sT_all)),
            torch.cat((sT_all, s0_all)),
            rows_all.repeat(2, 1, 1),
            mask_all.repeat(2, 1),
            floor_all.repeat(2, 1),
        )
    tm.families = tuple(f for f in FAMILIES if f in seen)  # recorded in its checkpoints
    tm.distilled = config.teacher if config.loss.imitation > 0 else None
    tm.body = body.name if config.body == "analytic" else None  # the sphere set it learned through
    if not tm.distilled:  # the sampler's paths filtered the pool; they are no target
        experts = None
    loop = iteration_loop(
        tm,
        config,
        run_dir,
        "tm_obstacles.pt",
        lambda path, extra: save_obstacle_model(tm, path, extra=extra),
        kind=ObstaclePathModel.kind,
        robot=robot.name,
        generator=gen,
        resume=resume,
        write_config=write_config,
        desc="obstacle TM training",
        progress=progress,
        postfix=("train/loss", "train/best_free"),
    )

    def step(_: int) -> dict[str, float]:
        idx = torch.randint(n_pool, (config.batch_size,), generator=gen)
        swap = torch.rand(config.batch_size, generator=gen) < 0.5
        s0, sT, scene = _batch(pool, ef_all, idx, swap)
        # Stratified: each segment is looked at once per stretch of 1/points, at a random place in it.
        fractions = (torch.arange(config.points) + torch.rand(config.points, generator=gen)) / config.points
        target = None
        if experts is not None:  # walked the other way where the problem is
            target = torch.where(swap[:, None, None], experts[idx].flip(1), experts[idx])
        box = (box_all[0][idx], box_all[1][idx])
        per, terms = candidate_losses(tm, body, s0, sT, scene, config.loss, fractions, expert=target, box=box)
        best = per.min(dim=1)
        total = best.values.mean() + config.loss.spread * per.mean()
        imitated = {}
        if target is not None:
            has = found[idx].to(per.dtype)
            nearest = terms.pop("imitation").min(dim=1).values  # the nearest candidate's, per problem
            imitation = (nearest * has).sum() / has.sum().clamp_min(1.0)  # over the problems with a path
            total = total + config.loss.imitation * imitation
            imitated = {"train/imitation": float(imitation.detach())}
        loss = loop.step(total, check=True)
        rows = torch.arange(per.shape[0])
        logged = {f"train/best_{k}": float(v.detach()[rows, best.indices].mean()) for k, v in terms.items()}
        free = (terms["collision"].detach()[rows, best.indices] == 0).float().mean()
        return {"train/loss": float(loss), **logged, "train/best_free": float(free), **imitated}

    loop.run(step)
    return tm
