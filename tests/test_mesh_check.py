"""The independent check against the URDF's own collision geometry (coal through pinocchio): it sees
obstacles, the floor and self-collision where they are, and a configuration the fitted spheres call free
is free under the geometry too."""

import numpy as np
import pytest
import torch

from kinlearn import load_robot, register_robot
from kinlearn.body.robot import unregister_robot
from kinlearn.collision.body import body_spheres
from kinlearn.collision.check import in_collision
from kinlearn.collision.geometry import Box, Sphere
from kinlearn.collision.mesh import MeshBody, mesh_check
from kinlearn.collision.scene import Scene
from kinlearn.collision.spherize import SpherizeConfig, spherize, write_sphere_model
from kinlearn.errors import RobotDescriptionError, ShapeError

ARM = """<?xml version="1.0"?>
<robot name="toy">
  <link name="base"><collision><origin xyz="0 0 0.05"/><geometry><cylinder radius="0.08" length="0.1"/></geometry></collision></link>
  <link name="l1"><collision><origin xyz="0 0 0.1"/><geometry><box size="0.08 0.08 0.2"/></geometry></collision></link>
  <link name="l2"><collision><origin xyz="0.15 0 0" rpy="0 1.5707963 0"/><geometry><cylinder radius="0.04" length="0.3"/></geometry></collision></link>
  <link name="l3"><collision><origin xyz="0.12 0 0"/><geometry><box size="0.24 0.06 0.06"/></geometry></collision></link>
  <link name="tool"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" velocity="2" effort="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.2"/><axis xyz="0 1 0"/><limit lower="-1.8" upper="1.8" velocity="2" effort="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0.3 0 0"/><axis xyz="0 1 0"/><limit lower="-2.6" upper="2.6" velocity="2" effort="1"/></joint>
  <joint name="tip" type="fixed"><parent link="l3"/><child link="tool"/><origin xyz="0.24 0 0"/></joint>
</robot>
"""
FAST = SpherizeConfig(fit_points=800, check_points=4000, voxels=16, candidates=250, radii=12, samples=300)


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    folder = tmp_path_factory.mktemp("mesh")
    path = folder / "toy.urdf"
    path.write_text(ARM)
    fit = spherize(load_robot(path, "tool"), config=FAST)
    model = write_sphere_model(fit, load_robot(path, "tool"), folder)
    robot = register_robot("toy_mesh", path, "tool", spheres=model)
    yield robot, MeshBody(robot)
    unregister_robot("toy_mesh")


def test_obstacles_floor_and_self_collision_are_seen(toy):
    robot, mesh = toy
    stretched = np.array([[0.0, 0.0, 0.0]])  # the arm along +x at 0.3 m height: l2 spans x 0…0.3
    on_arm = Scene.from_primitives([Box((0.15, 0.0, 0.3), (0.02, 0.02, 0.02))])
    beside = Scene.from_primitives([Box((0.15, 0.2, 0.3), (0.02, 0.02, 0.02))])
    assert mesh.collides(stretched, on_arm).tolist() == [True]
    assert mesh.collides(stretched, beside).tolist() == [False]
    # a ball just touching the tool box's end face (x = 0.54) and one 5 mm beyond it
    assert mesh.collides(stretched, Scene.from_primitives([Sphere((0.56, 0.0, 0.3), 0.021)])).tolist() == [
        True
    ]
    assert mesh.collides(stretched, Scene.from_primitives([Sphere((0.56, 0.0, 0.3), 0.015)])).tolist() == [
        False
    ]
    # the floor: the arm bent down through it collides, the base (standing on it) does not
    down = np.array([[0.0, 1.6, 0.0]])
    assert mesh.collides(down, Scene.from_primitives([], floor=0.0)).tolist() == [True]
    assert mesh.collides(stretched, Scene.from_primitives([], floor=0.0)).tolist() == [False]
    # self-collision: links two or more apart are checked, neighbours are not
    assert {tuple(sorted((int(mesh.link[a]), int(mesh.link[b])))) for a, b in mesh.self_pairs} == {
        (0, 2),
        (0, 3),
        (1, 3),
    }
    q = robot.sample(300, torch.Generator().manual_seed(1), dtype=torch.float64).numpy()
    folded = mesh.collides(q)
    assert 0 < folded.sum() < len(q)
    assert mesh.collides(np.array([[0.0, 1.2, 2.4]])).tolist() == [True]  # the tool box folded into the base


def test_configurations_free_under_the_spheres_are_free_under_the_geometry(toy):
    robot, mesh = toy
    body = body_spheres(robot).double()
    gen = torch.Generator().manual_seed(0)
    q = robot.sample(150, gen, dtype=torch.float64)
    scene = Scene.from_primitives(
        [
            Box((0.3, 0.1, 0.35), (0.06, 0.06, 0.06)),
            Sphere((0.0, -0.3, 0.4), 0.08),
            Box((-0.25, 0.2, 0.1), (0.05, 0.1, 0.1)),
        ],
        floor=0.0,
    ).to(torch.float64)
    spheres_hit = in_collision(body, q, scene).numpy()
    mesh_hit = mesh.collides(q.numpy(), scene)
    assert mesh_hit.any() and (~mesh_hit).any()  # not a vacuous comparison
    assert not (mesh_hit & ~spheres_hit).any()  # every geometry collision is a sphere collision


def test_a_path_through_an_obstacle_is_caught_between_its_knots(toy):
    _, mesh = toy
    scene = Scene.from_primitives([Box((0.0, 0.3, 0.3), (0.03, 0.03, 0.03))])
    path = np.array(
        [[[0.0, 0.0, 0.0], [3.0, 0.0, 0.0]]]
    )  # j1 turns the stretched arm past +y, where the box is
    assert not mesh.collides(path[0], scene).any()  # both ends are free
    assert mesh_check(mesh, path, scene).tolist() == [False]
    assert mesh_check(mesh, path[:, :, :] * np.array([0.1, 1, 1]), scene).tolist() == [True]
    with pytest.raises(ShapeError):
        mesh_check(mesh, np.zeros((2, 4)), scene)


def test_a_urdf_without_collision_geometry_is_refused(tmp_path):
    bare = tmp_path / "bare.urdf"
    bare.write_text(ARM.replace("<collision>", "<visual>").replace("</collision>", "</visual>"))
    with pytest.raises(RobotDescriptionError, match="no <collision>"):
        MeshBody(load_robot(bare, "tool"))
