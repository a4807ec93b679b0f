"""Your own arm from a URDF file: register it, babble, identify its chain from the observations, and
solve end-effector goals on it.

    python examples/05_your_own_arm.py
"""

import tempfile
from pathlib import Path

import torch

import kinlearn
from kinlearn.models.chain import solve_position
from kinlearn.training.identify import IdentifyConfig

URDF = """<?xml version="1.0"?>
<robot name="myarm">
  <link name="mount"/><link name="turret"/><link name="upper"/><link name="fore"/><link name="wrist"/>
  <link name="hand"/><link name="tcp"/>
  <joint name="j_turret" type="revolute"><parent link="mount"/><child link="turret"/>
    <origin xyz="0 0 0.12"/><axis xyz="0 0 1"/><limit lower="-2.8" upper="2.8" velocity="1.5" effort="40"/></joint>
  <joint name="j_shoulder" type="revolute"><parent link="turret"/><child link="upper"/>
    <origin xyz="0.05 0 0.20" rpy="0 0 0.1"/><axis xyz="0 1 0"/><limit lower="-1.6" upper="1.9" velocity="1.5" effort="40"/></joint>
  <joint name="j_elbow" type="revolute"><parent link="upper"/><child link="fore"/>
    <origin xyz="0 0.03 0.35"/><axis xyz="0 1 0"/><limit lower="-2.4" upper="2.4" velocity="2.0" effort="20"/></joint>
  <joint name="j_roll" type="revolute"><parent link="fore"/><child link="wrist"/>
    <origin xyz="0 0 0.28"/><axis xyz="0 0 1"/><limit lower="-3.0" upper="3.0" velocity="3.0" effort="10"/></joint>
  <joint name="j_pitch" type="revolute"><parent link="wrist"/><child link="hand"/>
    <origin xyz="0 0 0.06"/><axis xyz="1 0 0"/><limit lower="-2.0" upper="2.0" velocity="3.0" effort="10"/></joint>
  <joint name="j_tcp" type="fixed"><parent link="hand"/><child link="tcp"/><origin xyz="0 0.02 0.12"/></joint>
</robot>
"""
path = Path(tempfile.mkdtemp()) / "myarm.urdf"
path.write_text(URDF)
robot = kinlearn.register_robot("myarm", path, ee_frame="tcp")

data = kinlearn.data.babble(kinlearn.data.BabblingConfig(robot="myarm", walkers=100, steps=60, ef_noise=5e-4))
result = kinlearn.train.identify(data, robot="myarm", prior=False, config=IdentifyConfig(mlp_steps=400))
print(
    f"identified in {result.report['seconds']:.1f} s; held-out residual "
    f"{result.report['holdout_residual']['median'] * 1e3:.2f} mm"
)

gen = torch.Generator().manual_seed(2)
start = robot.sample(20, gen, dtype=torch.float64)
goal = kinlearn.kinematics(robot).position(robot.sample(20, gen, dtype=torch.float64))
lo, hi = robot.limits(torch.float64)
joints, _ = solve_position(result.model, start, goal, lo, hi)
err = (kinlearn.kinematics(robot).position(joints) - goal).norm(dim=-1)
print(f"goals reached through the identified chain: median error {float(err.median()) * 1e3:.3f} mm")
assert float(err.median()) < 1e-3
