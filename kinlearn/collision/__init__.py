"""Collision geometry for obstacle-aware planning: the arm's body as spheres, obstacle scenes,
batched differentiable signed distances, dense path checks and a benchmark problem generator.

Imports only from the robot, kinematics, errors and io layers.
"""

from .body import BodySpheres, body_spheres, cover_cylinder, sphere_sets
from .check import PathCheck, check_path, clearances, in_collision, segment_steps
from .distance import (
    body_obstacle_distance,
    self_collision_distance,
    sphere_box_distance,
    sphere_plane_distance,
    sphere_sphere_distance,
)
from .fast import NumpyBody, NumpyScene, check_paths, first_free
from .scene import Scene

__all__ = [
    "BodySpheres",
    "NumpyBody",
    "NumpyScene",
    "PathCheck",
    "Scene",
    "body_obstacle_distance",
    "body_spheres",
    "check_path",
    "check_paths",
    "clearances",
    "cover_cylinder",
    "first_free",
    "in_collision",
    "segment_steps",
    "self_collision_distance",
    "sphere_box_distance",
    "sphere_plane_distance",
    "sphere_sets",
    "sphere_sphere_distance",
]
