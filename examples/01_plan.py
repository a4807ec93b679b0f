"""Plan a move of the iiwa14 with the planner kinlearn ships, and look at what it says of itself.

python examples/01_plan.py
"""

import torch

import kinlearn

start = torch.tensor([-1.2, 0.9, 0.5, -1.6, 0.3, 1.2, -2.0])
goal = torch.tensor([1.5, -0.4, -0.8, 1.1, -1.9, -0.6, 2.4])
plan = kinlearn.plan(start, goal)
print(plan.summary())
assert bool(plan.success), "the shipped planner reaches held-out goal states"
print(
    "joint path", tuple(plan.joints.shape), "ends at the goal:", bool(torch.allclose(plan.joints[-1], goal))
)

traj = plan.timed()  # times, positions, velocities and accelerations within the joint limits
print(f"executes in {float(traj.t[-1]):.2f} s")
