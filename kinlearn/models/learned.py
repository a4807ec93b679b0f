"""The learned forward and inverse models (MLPs; the paper's Sect. 4, Cibula et al., ICANN 2024, Sect. 4.1):

- :class:`LearnedFM`: input [s, a] → shared dense layer(s) → a joints head (→ θ') and an ef head
  (→ ef'). Paper: shared 30 tanh; heads 20 tanh → 7 linear and 20 tanh → 3 linear.
- :class:`LearnedIM`: input [s, ef_target] → dense 40-60-60-40 tanh → dof linear (the action).

Options beyond the paper (off in the ``paper`` preset): ``normalize`` (inputs and outputs
standardised by buffers fitted on the training data with ``fit_normalization``),
``predict_delta`` (the FM predicts s' − s and adds s) and, for the IM, ``ef_delta_input`` (the IM
sees ef_target − ef instead of ef_target). See :class:`~kinlearn.models.configs.FMConfig` and
:class:`~kinlearn.models.configs.IMConfig`.
"""

from __future__ import annotations

import torch
from torch import nn

from .configs import FMConfig, IMConfig
from .interface import ForwardModel, InverseModel
from .layers import Normalizer, mlp

__all__ = ["LearnedFM", "LearnedIM"]


class LearnedFM(ForwardModel):
    """Learned forward model (see :class:`FMConfig`). Loss: sum of the two heads' MSE."""

    def __init__(self, config: FMConfig | None = None):
        config = config or FMConfig()
        super().__init__(config.robot, config.dof)
        self.config = config
        self.max_step = float(config.max_step)
        dof, S = config.dof, config.dof + 3
        n_in = S + dof
        self.shared = mlp((n_in, *config.shared), config.activation, None)
        width = config.shared[-1]
        self.joints_head = mlp((width, *config.joints_head), config.activation, dof)
        if config.ef_mode == "difference":
            # No output bias: a constant cancels in g(θ + a) − g(θ) and would never train.
            hidden = mlp((2 * dof, *config.fk_hidden), config.activation, None)
            self.fk = nn.Sequential(*hidden, nn.Linear(config.fk_hidden[-1], 3, bias=False))
        else:
            self.ef_head = mlp((width, *config.ef_head), config.activation, 3)
        if config.normalize:
            self.in_norm = Normalizer(n_in)
            self.out_norm = Normalizer(S)

    def config_dict(self) -> dict:
        return self.config.to_dict()

    def _inputs(self, s: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        x = torch.cat((s, a), dim=-1)
        return self.in_norm.encode(x) if self.config.normalize else x

    def _g(self, theta: torch.Tensor) -> torch.Tensor:
        """The learned function of the joints whose differences are the end-effector steps (metres)."""
        return self.fk(torch.cat((torch.sin(theta), torch.cos(theta)), dim=-1))

    def _raw(self, s: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        """Network output (normalised target space when ``normalize``) ``(..., S)``."""
        h = self.shared(self._inputs(s, a))
        if self.config.ef_mode == "head":
            return torch.cat((self.joints_head(h), self.ef_head(h)), dim=-1)
        theta = s[..., self.layout.joints]
        step = self._g(theta + a) - self._g(theta)
        if self.config.normalize:
            step = (step - self.out_norm.mean[self.layout.ef]) / self.out_norm.std[self.layout.ef]
        return torch.cat((self.joints_head(h), step), dim=-1)

    def ef_along(self, theta: torch.Tensor, ef0: torch.Tensor, every: int = 1) -> torch.Tensor:
        """See :meth:`ForwardModel.ef_along`. With ``ef_mode="difference"`` the rollout telescopes to
        ef(0) + g(θ(k)) − g(θ(0)), computed for the asked k at once (the same numbers as the
        step-by-step rollout, up to rounding)."""
        if self.config.ef_mode != "difference":
            return super().ef_along(theta, ef0, every)
        g = self._g(theta[:, ::every])
        return ef0.unsqueeze(1) + (g - g[:, :1])

    def _target(self, s: torch.Tensor, s_next: torch.Tensor) -> torch.Tensor:
        y = s_next - s if self.config.predict_delta else s_next
        return self.out_norm.encode(y) if self.config.normalize else y

    def _forward(self, s: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        y = self._raw(s, a)
        if self.config.normalize:
            y = self.out_norm.decode(y)
        return s + y if self.config.predict_delta else y

    def training_loss(self, s: torch.Tensor, a: torch.Tensor, s_next: torch.Tensor) -> torch.Tensor:
        """Sum of the joints head's and the ef head's MSE (in normalised units when ``normalize``)."""
        err = self._raw(s, a) - self._target(s, s_next)
        L = self.layout
        return err[..., L.joints].square().mean() + err[..., L.ef].square().mean()

    @torch.no_grad()
    def fit_normalization(self, s: torch.Tensor, a: torch.Tensor, s_next: torch.Tensor) -> None:
        """Fit the input/output statistics on training data (no-op without ``normalize``)."""
        if not self.config.normalize:
            return
        self.in_norm.fit(torch.cat((s, a), dim=-1))
        self.out_norm.fit(s_next - s if self.config.predict_delta else s_next)


class LearnedIM(InverseModel):
    """Learned (monolithic) inverse model (see :class:`IMConfig`). Loss: MSE of the action."""

    def __init__(self, config: IMConfig | None = None):
        config = config or IMConfig()
        super().__init__(config.robot, config.dof)
        self.config = config
        n_in = config.dof + 3 + 3
        self.net = mlp((n_in, *config.hidden), config.activation, config.dof)
        if config.normalize:
            self.in_norm = Normalizer(n_in)
            self.out_norm = Normalizer(config.dof)

    def config_dict(self) -> dict:
        return self.config.to_dict()

    def _inputs(self, s: torch.Tensor, ef_target: torch.Tensor) -> torch.Tensor:
        if self.config.ef_delta_input:
            ef_target = ef_target - s[..., self.layout.ef]
        x = torch.cat((s, ef_target), dim=-1)
        return self.in_norm.encode(x) if self.config.normalize else x

    def _raw(self, s: torch.Tensor, ef_target: torch.Tensor) -> torch.Tensor:
        return self.net(self._inputs(s, ef_target))

    def _forward(self, s: torch.Tensor, ef_target: torch.Tensor) -> torch.Tensor:
        y = self._raw(s, ef_target)
        return self.out_norm.decode(y) if self.config.normalize else y

    def training_loss(self, s: torch.Tensor, a: torch.Tensor, s_next: torch.Tensor) -> torch.Tensor:
        """MSE of the predicted action (in normalised units when ``normalize``)."""
        target = self.out_norm.encode(a) if self.config.normalize else a
        return (self._raw(s, s_next[..., self.layout.ef]) - target).square().mean()

    @torch.no_grad()
    def fit_normalization(self, s: torch.Tensor, a: torch.Tensor, s_next: torch.Tensor) -> None:
        """Fit the input/output statistics on training data (no-op without ``normalize``)."""
        if not self.config.normalize:
            return
        ef_t = s_next[..., self.layout.ef]
        if self.config.ef_delta_input:
            ef_t = ef_t - s[..., self.layout.ef]
        self.in_norm.fit(torch.cat((s, ef_t), dim=-1))
        self.out_norm.fit(a)
