"""Collision geometry for obstacle-aware planning: the arm's body as spheres, obstacle scenes of typed
primitives (spheres, oriented boxes, cylinders, a floor; MoveIt scenes in and out), batched
differentiable signed distances, dense path checks and a benchmark problem generator. The compiled
batch-1 kernels are :mod:`kinlearn.collision.kernel` (imported on its own: it loads numba).

Imports only from the robot, kinematics, errors and io layers.
"""

from .body import BodySpheres, body_spheres, cover_cylinder, planning_body, sphere_sets
from .check import PathCheck, check_path, clearances, in_collision, segment_steps
from .distance import (
    body_obstacle_distance,
    self_collision_distance,
    sphere_box_distance,
    sphere_cylinder_distance,
    sphere_distance,
    sphere_plane_distance,
    sphere_sphere_distance,
)
from .geometry import KINDS, Box, Cylinder, Plane, Primitive, Sphere
from .scene import Scene

__all__ = [
    "KINDS",
    "BodySpheres",
    "Box",
    "Cylinder",
    "PathCheck",
    "Plane",
    "Primitive",
    "Scene",
    "Sphere",
    "body_obstacle_distance",
    "body_spheres",
    "check_path",
    "clearances",
    "cover_cylinder",
    "in_collision",
    "planning_body",
    "segment_steps",
    "self_collision_distance",
    "sphere_box_distance",
    "sphere_cylinder_distance",
    "sphere_distance",
    "sphere_plane_distance",
    "sphere_sets",
    "sphere_sphere_distance",
]
