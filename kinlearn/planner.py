"""Planning with a trained trajectory model: ``plan(s0, sT)`` and :class:`Planner`.

A plan is computed in three batched passes: the TM predicts the end-effector waypoints, the IM and
FM roll out from the start through them to the goal (Algorithm 1; the actions are paper Eq. 2's
action sequence over consecutive states), and the joint path θ(0) + cumulative actions is checked
against the analytic FK, which gives the end-effector positions that executing the plan reaches.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import torch

from .errors import ConfigError, ShapeError, StateError
from .kinematics import kinematics
from .plan import Plan
from .rectify import rectify
from .robot import Robot, check_finite, load_robot
from .state import StateLayout
from .train_tm import TMTrainConfig, build_fm_im, load_tm
from .trajectory import TrajectoryModel

__all__ = ["DEFAULT_CHECKPOINTS", "Planner", "plan"]

#: Checkpoints shipped inside the package, produced by ``kinlearn make-default`` (see docs/usage.md).
DEFAULT_CHECKPOINTS = Path(__file__).resolve().parent / "checkpoints"

#: A full state's end effector may differ from FK of its joints by at most this much (m).
STATE_EF_TOLERANCE = 1e-3


class Planner:
    """A trajectory model with its frozen FM and IM, for one robot."""

    def __init__(
        self,
        robot: Robot,
        tm: TrajectoryModel,
        fm: torch.nn.Module,
        im: torch.nn.Module,
        refine: int = 1,
        exact_joints: bool = True,
    ):
        """``refine`` and ``exact_joints`` set the plan-time rollout (see :func:`~kinlearn.rectify.rectify`):
        by default one model-based correction of each action and the joints kept at θ(0) + Σ â, which
        took the shipped planner from 38% to 93% of held-out plans ending within 1 cm of the goal.
        ``refine=0, exact_joints=False`` is the paper's Algorithm 1 as published."""
        if refine < 0:
            raise ConfigError(f"refine must be ≥ 0, got {refine}")
        self.refine, self.exact_joints = int(refine), bool(exact_joints)
        for what, m in (("TM", tm), ("FM", fm), ("IM", im)):
            if getattr(m, "robot_name", robot.name) != robot.name:
                raise ConfigError(
                    f"the {what} was trained for {m.robot_name!r}, the planner is for {robot.name!r}"
                )
        self.robot = robot
        self.layout = StateLayout(robot.dof)
        self.tm, self.fm, self.im = tm.eval(), fm.eval(), im.eval()
        for m in (self.tm, self.fm, self.im):
            m.requires_grad_(False)
        for m in (self.fm, self.im):  # the planner checks its inputs once; no per-call re-checks
            m.validate_inputs = False
        self.kin = kinematics(robot)
        self._core = self._rollout
        self._lo, self._hi = robot.limits(torch.float64)

    @classmethod
    def load(cls, run_dir: str | Path, robot: str | None = None, **rollout) -> Planner:
        """Load a trained run: ``run_dir/tm.pt``, with ``fm.pt``/``im.pt`` from ``run_dir`` if present,
        else from the run's ``models_dir``; analytic FM/IM where the run used them. ``rollout``:
        ``refine``, ``exact_joints`` (see :meth:`__init__`)."""
        run_dir = Path(run_dir)
        if not (run_dir / "tm.pt").is_file():
            raise ConfigError(
                f"{run_dir} holds no tm.pt; train one with `kinlearn train-tm --run-dir {run_dir}`"
            )
        tm, config = load_tm(run_dir / "tm.pt", robot=robot)
        if (run_dir / "fm.pt").is_file() or (run_dir / "im.pt").is_file():
            config = TMTrainConfig.from_dict({**config.to_dict(), "models_dir": str(run_dir)})
        fm, im = build_fm_im(config)
        return cls(load_robot(config.robot), tm, fm, im, **rollout)

    @classmethod
    def default(cls, robot: str = "iiwa14") -> Planner:
        """The small planner shipped with kinlearn (learned FM, IM and TM)."""
        return _default_planner(robot)

    def _states(self, start, goal) -> tuple[torch.Tensor, torch.Tensor]:
        """Check start and goal (one pass over both) and return them as full states ``(..., S)``."""
        dof, S = self.robot.dof, self.layout.size
        pair = []
        for what, x in (("start", start), ("goal", goal)):
            x = torch.as_tensor(x)
            if not x.is_floating_point():
                x = x.to(torch.get_default_dtype())
            if x.ndim == 0 or x.shape[-1] not in (dof, S):
                raise ShapeError(
                    f"{what} must have shape (..., {S}) (a state [θ, ef]) or (..., {dof}) (joint values) "
                    f"for {self.robot.name}; got {tuple(x.shape)}"
                )
            pair.append(x)
        (x0, xT), dtype = pair, torch.promote_types(pair[0].dtype, pair[1].dtype)
        try:
            batch = torch.broadcast_shapes(x0.shape[:-1], xT.shape[:-1])
        except RuntimeError as exc:
            raise ShapeError(f"start {tuple(x0.shape)} and goal {tuple(xT.shape)} do not broadcast") from exc
        theta = torch.stack([x[..., self.layout.joints].to(dtype).expand(*batch, dof) for x in (x0, xT)])
        lo, hi = self._lo.to(dtype), self._hi.to(dtype)
        if not bool(((theta >= lo - 1e-6) & (theta <= hi + 1e-6)).all()):  # also false for NaN
            for what, x in (("start", x0), ("goal", xT)):
                check_finite(x, what)
                self.robot.check_joints(x[..., self.layout.joints], what=f"{what} joints")
        ef = self.kin.position(theta, validate=False)
        out = []
        for k, (what, x) in enumerate((("start", x0), ("goal", xT))):
            if x.shape[-1] == S:
                check_finite(x[..., self.layout.ef], what)
                err = (x[..., self.layout.ef].to(dtype) - ef[k]).norm(dim=-1)
                if bool((err > STATE_EF_TOLERANCE).any()):
                    raise StateError(
                        f"{what}: its end-effector part differs from FK of its joints by up to "
                        f"{float(err.max()):.4g} m (allowed {STATE_EF_TOLERANCE} m); pass joint values alone "
                        "to have ef computed"
                    )
            out.append(self.layout.join(theta[k], ef[k]))
        return out[0], out[1]

    def _rollout(self, s0: torch.Tensor, sT: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """TM waypoints and the IM/FM rollout's actions for flat ``(N, S)`` states (network dtype)."""
        waypoints = self.tm(s0, sT)
        _, actions = rectify(
            waypoints,
            s0,
            sT,
            self.fm,
            self.im,
            self.layout,
            refine=self.refine,
            exact_joints=self.exact_joints,
        )
        return waypoints, actions

    def compile(self, **options) -> Planner:
        """Compile the TM + rollout with ``torch.compile`` (first calls per input shape are slow).

        Plans stay the same up to floating-point rounding; returns ``self``.
        """
        self._core = torch.compile(self._rollout, dynamic=False, **options)
        return self

    @torch.no_grad()
    def plan(self, start, goal) -> Plan:
        """Plan from ``start`` to ``goal``: states ``(..., dof + 3)`` or joint values ``(..., dof)``.

        Leading batch dimensions broadcast. Deterministic: the same input gives the same plan bit for
        bit. Raises :class:`ShapeError`, :class:`NonFiniteError`, :class:`JointLimitError` or
        :class:`StateError` for bad input. Outputs have the input's dtype.
        """
        s0, sT = self._states(start, goal)
        dtype, batch, S, dof = s0.dtype, s0.shape[:-1], self.layout.size, self.robot.dof
        net_dtype = self.tm.in_mean.dtype
        flat0, flatT = s0.reshape(-1, S), sT.reshape(-1, S)
        waypoints, actions = self._core(flat0.to(net_dtype), flatT.to(net_dtype))
        actions = actions.to(dtype)
        theta0 = flat0[:, None, self.layout.joints]
        joints = torch.cat((theta0, theta0 + torch.cumsum(actions, dim=1)), dim=1)
        ef = self.kin.position(joints, validate=False)
        T = actions.shape[1]
        return Plan(
            start=s0,
            goal=sT,
            waypoints=waypoints.to(dtype).reshape(*batch, T - 1, 3),
            actions=actions.reshape(*batch, T, dof),
            joints=joints.reshape(*batch, T + 1, dof),
            ef=ef.reshape(*batch, T + 1, 3),
        )

    __call__ = plan


@lru_cache(maxsize=8)
def _default_planner(robot: str) -> Planner:
    path = DEFAULT_CHECKPOINTS / robot
    if not (path / "tm.pt").is_file():
        raise ConfigError(
            f"kinlearn ships a default planner for iiwa14 only (none at {path}); train one for {robot!r} "
            "with `kinlearn reproduce` or `kinlearn train-tm` and load it with Planner.load(run_dir)"
        )
    return Planner.load(path, robot=robot)


def plan(start, goal, robot: str = "iiwa14") -> Plan:
    """Plan with the default planner shipped for ``robot`` (see :meth:`Planner.plan`)."""
    return Planner.default(robot).plan(start, goal)
