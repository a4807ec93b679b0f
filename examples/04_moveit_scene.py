"""Obstacles from a MoveIt planning scene: a table and a post, read into the robot's base frame, and a
plan around them, checked densely against the arm's collision spheres.

    python examples/04_moveit_scene.py
"""

import torch

import kinlearn
from kinlearn.collision import Scene

scene_yaml = {
    "world": {
        "collision_objects": [
            {
                "id": "table",
                "pose": {
                    "position": {"x": 0.75, "y": 0.0, "z": 0.1},
                    "orientation": {"x": 0, "y": 0, "z": 0, "w": 1},
                },
                "primitives": [{"type": "box", "dimensions": [0.6, 1.0, 0.05]}],
                "primitive_poses": [
                    {"position": {"x": 0, "y": 0, "z": 0}, "orientation": {"x": 0, "y": 0, "z": 0, "w": 1}}
                ],
            },
            {
                "id": "post",
                "primitives": [{"type": "cylinder", "dimensions": [0.6, 0.04]}],
                "primitive_poses": [
                    {
                        "position": {"x": -0.7, "y": 0.6, "z": 0.3},
                        "orientation": {"x": 0, "y": 0, "z": 0, "w": 1},
                    }
                ],
            },
        ]
    }
}
scene = Scene.from_moveit(scene_yaml)
print("obstacles:", [type(p).__name__ for p in scene.primitives()])
start = torch.tensor([-1.2, 0.9, 0.5, -1.6, 0.3, 1.2, -2.0], dtype=torch.float64)
goal = torch.tensor([1.0, 0.4, -0.8, -1.1, -1.9, -0.6, 2.4], dtype=torch.float64)
plan = kinlearn.plan(start, goal, obstacles=scene, refine_steps=25)
print(plan.summary())
print("collision free:", bool(plan.collision_free))
assert bool(plan.success)
