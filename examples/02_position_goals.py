"""End-effector position goals through the learned models alone: every shipped arm's kinematic chain
was identified from its own noisy babbling, with no URDF; the analytic FK only judges the result.

    python examples/02_position_goals.py
"""

import torch

import kinlearn

for name in kinlearn.available_robots():
    robot = kinlearn.load_robot(name)
    gen = torch.Generator().manual_seed(0)
    start = robot.sample(50, gen, dtype=torch.float64, margin=0.1)
    goal = kinlearn.kinematics(robot).position(robot.sample(50, gen, dtype=torch.float64, margin=0.1))
    plan = kinlearn.plan(start, goal_position=goal, robot=name)
    err_mm = plan.goal_error * 1000
    print(
        f"{name:7s} {float(plan.success.double().mean()):6.1%} within 1 cm, median {float(err_mm.median()):.3f} mm"
    )
