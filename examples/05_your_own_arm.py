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
<robot name="toy4">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="l4"/><link name="tool"/>
  <joint name="yaw" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit lower="-2.5" upper="2.5" velocity="2.0" effort="10"/></joint>
  <joint name="shoulder" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0 0.30"/><axis xyz="0 1 0"/><limit lower="-1.8" upper="1.8" velocity="2.0" effort="10"/></joint>
  <joint name="elbow" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="0 0 0.25"/><axis xyz="0 1 0"/><limit lower="-2.2" upper="2.2" velocity="2.5" effort="10"/></joint>
  <joint name="wrist" type="revolute"><parent link="l3"/><child link="l4"/>
    <origin xyz="0.02 0 0.20"/><axis xyz="0 1 0"/><limit lower="-2.0" upper="2.0" velocity="3.0" effort="10"/></joint>
  <joint name="flange" type="fixed"><parent link="l4"/><child link="tool"/><origin xyz="0 0 0.10"/></joint>
</robot>
"""
path = Path(tempfile.mkdtemp()) / "toy4.urdf"
path.write_text(URDF)
robot = kinlearn.register_robot("toy4", path, ee_frame="tool")

data = kinlearn.babble(kinlearn.BabblingConfig(robot="toy4", walkers=100, steps=60, ef_noise=5e-4))
result = kinlearn.identify(data, robot="toy4", prior=False, config=IdentifyConfig(mlp_steps=400))
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
