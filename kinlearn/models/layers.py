"""The building blocks of the learned FM and IM: dense layers with a named activation, and an affine
normaliser whose statistics are buffers (they travel with the checkpoint and with ``.to()``)."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Literal

import torch
from torch import nn

__all__ = ["ACTIVATIONS", "Activation", "Normalizer", "mlp"]

Activation = Literal["tanh", "relu", "gelu", "silu", "elu"]
ACTIVATIONS: dict[str, type[nn.Module]] = {
    "tanh": nn.Tanh,
    "relu": nn.ReLU,
    "gelu": nn.GELU,
    "silu": nn.SiLU,
    "elu": nn.ELU,
}


def mlp(sizes: Sequence[int], activation: str, linear_out: int | None) -> nn.Sequential:
    """Dense layers through ``sizes`` with ``activation`` after each, then an optional linear output."""
    layers: list[nn.Module] = []
    for n_in, n_out in itertools.pairwise(sizes):
        layers += [nn.Linear(n_in, n_out), ACTIVATIONS[activation]()]
    if linear_out is not None:
        layers.append(nn.Linear(sizes[-1], linear_out))
    return nn.Sequential(*layers)


class Normalizer(nn.Module):
    """Affine standardisation ``(x − mean) / std`` with the statistics held as buffers."""

    def __init__(self, n: int):
        super().__init__()
        self.register_buffer("mean", torch.zeros(n))
        self.register_buffer("std", torch.ones(n))

    @torch.no_grad()
    def fit(self, x: torch.Tensor, min_std: float = 1e-6) -> None:
        x = x.reshape(-1, x.shape[-1]).double()
        self.mean.copy_(x.mean(0))
        self.std.copy_(x.std(0).clamp_min(min_std))

    def encode(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.mean.to(x.dtype)) / self.std.to(x.dtype)

    def decode(self, y: torch.Tensor) -> torch.Tensor:
        return y * self.std.to(y.dtype) + self.mean.to(y.dtype)
