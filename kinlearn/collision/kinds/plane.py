"""The plane kind: a half-space, one row ``[nx, ny, nz, offset]``, solid where n · p ≤ offset. A scene
holds its floor as a height, not as a table (the kernels take it as ``floor = [has floor, height]``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import torch

from ...errors import ObstacleError
from .primitive import Primitive, vec

__all__ = ["NORMAL", "OFFSET", "Plane"]

#: The row's columns: the unit normal, then the offset along it.
NORMAL, OFFSET = slice(0, 3), 3


@dataclass(frozen=True)
class Plane(Primitive):
    """A half-space: unit ``normal`` (3,) and ``offset``; solid where normal · p ≤ offset. A floor at
    height h is ``Plane((0, 0, 1), h)`` (a :class:`~kinlearn.collision.Scene` keeps its floor as that
    height)."""

    kind: ClassVar[str] = "plane"
    table: ClassVar[str] = "planes"
    width: ClassVar[int] = 4
    layout: ClassVar[str] = "[nx, ny, nz, offset]"
    sizes: ClassVar[slice] = slice(0, 0)
    size_name: ClassVar[str] = "size"
    pad: ClassVar[tuple[float, ...]] = (0.0, 0.0, 1.0, -1000.0)
    packed_width: ClassVar[int] = 4

    normal: tuple[float, float, float]
    offset: float

    def __post_init__(self):
        n = np.asarray(vec(self.normal, 3, "a plane's normal"))
        norm = float(np.linalg.norm(n))
        if not norm > 0:
            raise ObstacleError("a plane's normal must not be zero")
        object.__setattr__(self, "normal", tuple(float(v) for v in n / norm))
        object.__setattr__(self, "offset", float(vec([self.offset], 1, "a plane's offset")[0]))

    def row(self) -> tuple[float, ...]:
        return (*self.normal, self.offset)

    @classmethod
    def from_row(cls, row) -> Plane:
        return cls(tuple(row[NORMAL]), row[OFFSET])

    @staticmethod
    def point_distance(p: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
        return (
            p[..., 0] * rows[..., 0] + p[..., 1] * rows[..., 1] + p[..., 2] * rows[..., 2] - rows[..., OFFSET]
        )
