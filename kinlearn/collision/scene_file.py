"""Scene files: a :class:`~kinlearn.collision.scene.Scene` kept as an ``.npz`` of its arrays (float64
and bool, keyed by field, as ``Scene.arrays`` gives them), with the robot whose base frame it is in and
the layout's version (:data:`SCENE_FORMAT`). A point cloud is kept as its points and its sizes
(radius, resolution, contact; a file without the contact reads the default); its distance grid is built again when it is read. :func:`write_scene` writes
atomically; :func:`read_scene` refuses a file of another kind, robot or format with a
:class:`~kinlearn.errors.DatasetError`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import DatasetError
from ..io import load_npz, save_npz

__all__ = ["SCENE_FORMAT", "SCENE_FORMATS", "cloud_arrays", "cloud_from_arrays", "read_scene", "write_scene"]

#: Version of the scene ``.npz`` layout written by :meth:`Scene.save` (2: oriented boxes, cylinders; a
#: scene with a point cloud is written as 3, which older readers refuse rather than drop its points).
SCENE_FORMAT = 2
#: Scene formats :meth:`Scene.load` reads (1: spheres and axis-aligned boxes; 3: with a point cloud).
SCENE_FORMATS = (1, 2, 3)


def cloud_arrays(cloud) -> dict[str, np.ndarray]:
    """A :class:`~kinlearn.collision.cloud.PointCloud`'s arrays in a scene file: its points, sizes and contact."""
    return {
        "cloud_points": np.array(cloud.points),
        "cloud_sizes": np.array([cloud.radius, cloud.resolution, cloud.contact]),
    }


def cloud_from_arrays(arrays: dict[str, np.ndarray]):
    """The :class:`~kinlearn.collision.cloud.PointCloud` a scene's arrays hold, or None."""
    if "cloud_points" not in arrays:
        return None
    from .cloud import PointCloud

    sizes = [float(v) for v in np.asarray(arrays["cloud_sizes"]).reshape(-1)]
    if len(sizes) not in (2, 3):  # (radius, resolution[, contact]): a file without contact reads the default
        raise DatasetError(f"a scene file's cloud_sizes must hold 2 or 3 numbers, got {len(sizes)}")
    return PointCloud(np.asarray(arrays["cloud_points"]), *sizes)


def write_scene(path: str | Path, arrays: dict[str, np.ndarray], robot: str = "") -> Path:
    """Write a scene's ``arrays`` to ``path`` (``.npz``) atomically, as format :data:`SCENE_FORMAT` (3 for a
    scene with a point cloud); ``robot`` names the robot whose base frame it is in."""
    version = SCENE_FORMAT if "cloud_points" not in arrays else 3
    return save_npz(path, kind="scene", robot=robot, config={"scene_format": version}, arrays=arrays)


def read_scene(path: str | Path, robot: str | None = None) -> dict[str, np.ndarray]:
    """The arrays of a scene file written by :func:`write_scene`. Raises
    :class:`~kinlearn.errors.DatasetError` for a missing or unreadable file, a file of another kind,
    format or robot."""
    meta, arrays = load_npz(path, kind="scene", robot=robot)
    version = meta.get("config", {}).get("scene_format")
    if version not in SCENE_FORMATS:
        raise DatasetError(
            f"{path} holds scene format {version!r}; this kinlearn reads scene formats "
            f"{', '.join(map(str, SCENE_FORMATS))}"
        )
    return arrays
