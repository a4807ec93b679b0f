"""Spheres fitted to a URDF's own collision geometry: they cover every sampled surface point (checked on a
fresh sample, in the world, where pinocchio puts the links), are the same for the same seed, read back
through register_robot(spheres=...), carry an SRDF's disabled pairs, and URDFs that cannot be fitted are
refused with typed errors."""

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import torch

from kinlearn import load_robot, register_robot
from kinlearn.body.robot import unregister_robot
from kinlearn.collision.body import body_spheres
from kinlearn.collision.spherize import (
    SpherizeConfig,
    coverage,
    excess_volume,
    link_geometry,
    spherize,
    write_sphere_model,
)
from kinlearn.errors import ConfigError, RobotDescriptionError

#: Small fitting sizes: the same algorithm, fewer points.
FAST = SpherizeConfig(fit_points=800, check_points=4000, voxels=16, candidates=250, radii=12, samples=300)

ARM = """<?xml version="1.0"?>
<robot name="toy">
  <link name="base"><collision><origin xyz="0 0 0.05"/><geometry><cylinder radius="0.08" length="0.1"/></geometry></collision></link>
  <link name="l1"><collision><origin xyz="0 0 0.1"/><geometry><box size="0.08 0.08 0.2"/></geometry></collision></link>
  <link name="l2"><collision><origin xyz="0.15 0 0" rpy="0 1.5707963 0"/><geometry><cylinder radius="0.04" length="0.3"/></geometry></collision></link>
  <link name="l3"><collision><origin xyz="0.12 0 0"/><geometry><box size="0.24 0.06 0.06"/></geometry></collision></link>
  <link name="cap"><collision><geometry><sphere radius="0.035"/></geometry></collision></link>
  <link name="tool"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" velocity="2" effort="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.2"/><axis xyz="0 1 0"/><limit lower="-1.8" upper="1.8" velocity="2" effort="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0.3 0 0"/><axis xyz="0 1 0"/><limit lower="-2.5" upper="2.5" velocity="2" effort="1"/></joint>
  <joint name="capj" type="fixed"><parent link="l3"/><child link="cap"/><origin xyz="0.24 0 0"/></joint>
  <joint name="tip" type="fixed"><parent link="l3"/><child link="tool"/><origin xyz="0.26 0 0"/></joint>
</robot>
"""


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    path = tmp_path_factory.mktemp("toy") / "toy.urdf"
    path.write_text(ARM)
    return path, load_robot(path, "tool")


@pytest.fixture(scope="module")
def fit(arm):
    return spherize(arm[1], config=FAST)


def test_every_link_is_covered_on_a_fresh_sample_with_few_spheres(arm, fit):
    groups = [g for g in link_geometry(arm[1]) if g.parts]
    assert [g.index for g in groups] == [0, 1, 2, 3]
    for g in groups:
        s = fit.spheres[fit.spheres[:, 0] == g.index, 1:]
        assert 1 <= len(s) <= 12
        pts = g.sample(20000, np.random.default_rng(123))  # not the points it was fitted to
        cov = coverage(s, pts, tolerance=0.002)
        assert cov["inside"] >= 0.999, (g.name, cov)
        assert cov["beyond_tolerance"] == 0, (g.name, cov)
        ex = excess_volume(s, g)
        assert 0 < ex["excess"] < 3 * ex["union"]  # the union holds the solid, and not only air
    # link 3 carries the fixed sphere "cap" too: points on it are covered in link 3's frame
    cap = fit.spheres[fit.spheres[:, 0] == 3, 1:]
    v = np.random.default_rng(5).normal(size=(2000, 3))
    on_cap = 0.035 * v / np.linalg.norm(v, axis=1, keepdims=True) + [0.24, 0.0, 0.0]
    assert coverage(cap, on_cap)["beyond_tolerance"] == 0


def test_same_seed_same_spheres_another_seed_other_spheres(arm, fit):
    again = spherize(arm[1], config=FAST)
    np.testing.assert_array_equal(again.spheres, fit.spheres)
    other = spherize(arm[1], config=SpherizeConfig(**{**FAST.__dict__, "seed": 1}))
    assert other.spheres.shape != fit.spheres.shape or not np.array_equal(other.spheres, fit.spheres)


def test_written_model_reads_back_and_covers_the_links_where_pinocchio_puts_them(arm, fit, tmp_path):
    path, robot = arm
    model = write_sphere_model(fit, robot, tmp_path)
    try:
        mine = register_robot("toy_fitted", path, "tool", spheres=model)
        body = body_spheres(mine).double()
        np.testing.assert_allclose(body.local.numpy(), fit.spheres[:, 1:4], atol=1e-6)
        np.testing.assert_allclose(body.radii.numpy(), fit.spheres[:, 4], atol=1e-5)
        # the URDF alone reads back the same spheres
        by_urdf = register_robot(
            "toy_fitted", path, "tool", spheres=tmp_path / "toy_spherized.urdf", overwrite=True
        )
        np.testing.assert_allclose(body_spheres(by_urdf).local.numpy(), fit.spheres[:, 1:4], atol=1e-6)
        # in the world: surface points of each link, placed by pinocchio, lie in the spheres placed by kinlearn
        pm = pin.buildModelFromUrdf(str(path))
        data = pm.createData()
        groups = {g.index: g for g in link_geometry(robot) if g.parts}
        q = robot.sample(5, torch.Generator().manual_seed(3), dtype=torch.float64)
        centres = body(q).numpy()
        r = body.radii.numpy()
        for n in range(len(q)):
            pin.framesForwardKinematics(pm, data, q[n].numpy())
            for k, g in groups.items():
                M = data.oMf[pm.getFrameId(fit.links[k])]
                pts = g.sample(3000, np.random.default_rng(n)) @ M.rotation.T + M.translation
                on = fit.spheres[:, 0] == k
                world = np.concatenate([centres[n][on], r[on, None]], 1)
                assert coverage(world, pts)["beyond_tolerance"] == 0
    finally:
        unregister_robot("toy_fitted")


def test_srdf_pairs_are_left_out_of_self_collision(arm, tmp_path):
    path, robot = arm
    srdf = tmp_path / "toy.srdf"
    srdf.write_text('<robot name="toy"><disable_collisions link1="base" link2="l3" reason="Never"/></robot>')
    fit = spherize(robot, srdf=srdf, config=FAST)
    assert (0, 3) in fit.excluded_link_pairs
    assert fit.why[fit.excluded_link_pairs.index((0, 3))] == "srdf"
    # every other pair two apart meets somewhere in the joint range (link 2 swings down to the base, link 3
    # folds back onto link 1): none is left out as never touching
    assert fit.excluded_link_pairs == [(0, 3)]
    model = write_sphere_model(fit, robot, tmp_path)
    try:
        body = body_spheres(register_robot("toy_srdf", path, "tool", spheres=model))
        links = body.link[body.pairs].sort(dim=1).values.tolist()
        assert [0, 3] not in links
        assert [1, 3] in links and [0, 2] in links
    finally:
        unregister_robot("toy_srdf")


def test_the_shipped_xarm7_body_covers_its_meshes():
    robot = load_robot("xarm7")
    body = body_spheres(robot)
    assert body.name == "fitted"
    spheres = np.concatenate([body.link[:, None].numpy(), body.local.numpy(), body.radii[:, None].numpy()], 1)
    g = next(g for g in link_geometry(robot) if g.index == 7)
    cov = coverage(spheres[spheres[:, 0] == 7, 1:], g.sample(20000, np.random.default_rng(7)))
    assert cov["inside"] >= 0.999 and cov["beyond_tolerance"] == 0


def test_unfit_urdfs_are_refused_with_what_to_do(tmp_path):
    bare = tmp_path / "bare.urdf"
    bare.write_text(ARM.replace("<collision>", "<visual>").replace("</collision>", "</visual>"))
    with pytest.raises(RobotDescriptionError, match="no link of the chain carries <collision>"):
        spherize(load_robot(bare, "tool"), config=FAST)
    missing = tmp_path / "missing.urdf"
    missing.write_text(
        ARM.replace('<sphere radius="0.035"/>', '<mesh filename="package://nowhere/cap.stl"/>')
    )
    with pytest.raises(RobotDescriptionError, match="package_dirs"):
        spherize(load_robot(missing, "tool"), config=FAST)
    with pytest.raises(ConfigError, match="sphere_price"):
        SpherizeConfig(sphere_price=-1.0)


def test_a_mesh_file_is_read_through_trimesh(tmp_path):
    import trimesh

    trimesh.creation.box(extents=(0.1, 0.05, 0.2)).export(tmp_path / "block.stl")
    urdf = tmp_path / "m.urdf"
    urdf.write_text(
        ARM.replace('<box size="0.08 0.08 0.2"/>', '<mesh filename="block.stl" scale="0.8 1.6 1"/>')
    )
    robot = load_robot(urdf, "tool")
    g = next(g for g in link_geometry(robot) if g.index == 1)
    assert np.allclose(g.parts[0].mesh.extents, (0.08, 0.08, 0.2))
    s = spherize(robot, config=FAST).spheres
    assert coverage(s[s[:, 0] == 1, 1:], g.sample(5000, np.random.default_rng(0)))["beyond_tolerance"] == 0


def test_paths_resolve(arm):
    from kinlearn.collision.spherize import resolve_mesh_path

    here = Path(__file__)
    assert resolve_mesh_path(here.name, here) == here


def test_pairs_whose_meshes_never_meet_are_left_out_but_the_mesh_check_keeps_them(tmp_path):
    from kinlearn.collision.mesh import MeshBody

    narrow = tmp_path / "narrow.urdf"  # the shoulder and elbow barely move: links two apart never meet
    narrow.write_text(
        ARM.replace('lower="-1.8" upper="1.8"', 'lower="-0.3" upper="0.3"').replace(
            'lower="-2.5" upper="2.5"', 'lower="-0.5" upper="0.5"'
        )
    )
    robot = load_robot(narrow, "tool")
    fit = spherize(robot, config=FAST)
    assert (0, 2) in fit.excluded_link_pairs
    assert fit.why[fit.excluded_link_pairs.index((0, 2))].startswith("never touching")
    model = write_sphere_model(fit, robot, tmp_path)
    try:
        mine = register_robot("toy_narrow", narrow, "tool", spheres=model)
        links = body_spheres(mine).link[body_spheres(mine).pairs].sort(dim=1).values.tolist()
        assert [0, 2] not in links
        mesh = MeshBody(mine)
        assert (0, 2) in {tuple(sorted((int(mesh.link[a]), int(mesh.link[b])))) for a, b in mesh.self_pairs}
    finally:
        unregister_robot("toy_narrow")
