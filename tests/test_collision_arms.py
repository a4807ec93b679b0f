"""Collision bodies of the panda and the ur5 from their spherized URDFs: every sphere where pinocchio
(its own URDF and geometry parsers, an independent reading of the same files) puts it, the parts
kinlearn's ur5 lacks left out, self-collision pairs, distances against coal, and a user's arm
registered with ``spheres=``."""

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import torch

import kinlearn
from kinlearn import kinematics, load_robot
from kinlearn.collision import Scene, body_obstacle_distance, body_spheres, self_collision_distance
from kinlearn.collision.body import urdf_spheres
from kinlearn.collision.geometry import Box, Cylinder, Sphere, rotation_from_quaternion
from kinlearn.errors import ConfigError, RobotDescriptionError

ROBOTS = Path(__file__).resolve().parents[1] / "robots"
#: The links of kinlearn's ur5 that carry spheres (the sensor and gripper under ee_link are not its).
UR5_ARM = {
    "base_link",
    "shoulder_link",
    "upper_arm_link",
    "forearm_link",
    "wrist_1_link",
    "wrist_2_link",
    "wrist_3_link",
}


def _pinocchio_spheres(name: str, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World centres (in the spherized model's root) and radii of its spheres, by pinocchio, with
    the base_link frame's pose; the ur5 restricted to its arm's links."""
    path = str(ROBOTS / name / f"{name}_spherized.urdf")
    model = pin.buildModelFromUrdf(path)
    geom = pin.buildGeomFromUrdf(model, path, pin.GeometryType.COLLISION)
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    base = data.oMf[model.getFrameId("base_link" if name == "ur5" else "panda_link0")]
    centres, radii = [], []
    for obj in geom.geometryObjects:
        if name == "ur5" and model.frames[obj.parentFrame].name not in UR5_ARM:
            continue
        world = data.oMi[obj.parentJoint] * obj.placement
        centres.append((base.inverse() * world).translation)
        radii.append(obj.geometry.radius)
    return np.array(centres), np.array(radii)


def _root_from_base(robot) -> pin.SE3:
    """kinlearn's root frame → the arm's base_link frame, from pinocchio on kinlearn's own URDF."""
    model = pin.buildModelFromUrdf(str(robot.urdf_path))
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    base = "base_link" if robot.name == "ur5" else "panda_link0"
    return data.oMf[model.getFrameId(base)]


@pytest.mark.parametrize("name, count", [("panda", 59), ("ur5", 23)])
def test_spheres_sit_where_pinocchio_puts_them(name, count):
    robot = load_robot(name)
    body = body_spheres(robot).double()
    assert body.num_spheres == count and body.name == "spherized"
    q = robot.sample(5, torch.Generator().manual_seed(0), dtype=torch.float64)
    T = _root_from_base(robot)
    for qi in q:
        ours = body(qi).numpy()
        ours = (T.rotation.T @ (ours - T.translation).T).T  # into the base_link frame
        ref, radii = _pinocchio_spheres(name, qi.numpy())
        assert ref.shape == ours.shape
        # Same spheres, in any order: each of ours has a pinocchio sphere of its radius at its centre.
        d = np.linalg.norm(ours[:, None] - ref[None], axis=-1) + 10 * np.abs(
            body.radii.numpy()[:, None] - radii
        )
        # The ur5 file writes π/2 as 1.570796325: its frames agree with kinlearn's to 5e-9 m.
        assert d.min(axis=1).max() < (1e-8 if name == "ur5" else 1e-9)
        assert len(set(d.argmin(axis=1))) == count


def test_ur5_keeps_its_arm_drops_the_stand_and_carries_the_gripper_on_request():
    robot = load_robot("ur5")
    spheres = urdf_spheres(robot, ROBOTS / "ur5" / "ur5_spherized.urdf", ("ee_link",))
    assert np.bincount(spheres[:, 0].astype(int)).tolist() == [1, 1, 5, 9, 3, 3, 1]
    everything = urdf_spheres(robot, ROBOTS / "ur5" / "ur5_spherized.urdf")  # gripper folded onto wrist 3
    assert len(everything) == 40 and int((everything[:, 0] == 6).sum()) == 1 + 17  # sensor 1, gripper 16
    arm, tool = body_spheres(robot).double(), body_spheres(robot, sphere_set="gripper").double()
    assert arm.num_spheres == 23 and tool.num_spheres == 40 and tool.name == "gripper"
    assert np.allclose(np.sort(tool.radii.numpy()), np.sort(everything[:, 4]))
    # The tool reaches 0.1 m and more past the flange (along the last joint's axis); the arm does not.
    q = robot.sample(4, torch.Generator().manual_seed(2), dtype=torch.float64)
    flange = kinematics(robot, "fast").position(q).numpy()[:, None]

    def past(body):  # how far the last link's spheres reach from the flange
        last = body.link.numpy() == 6
        return (np.linalg.norm(body(q).numpy()[:, last] - flange, axis=-1) + body.radii.numpy()[last]).max(-1)

    assert (past(tool) > past(arm) + 0.1).all()
    with pytest.raises(RobotDescriptionError, match="no 'hand' sphere set"):
        body_spheres(robot, sphere_set="hand")
    with pytest.raises(ConfigError, match="not both"):
        body_spheres(robot, dense=True, sphere_set="gripper")


@pytest.mark.parametrize("name", ["panda", "ur5"])
def test_self_collision_pairs(name):
    robot = load_robot(name)
    body = body_spheres(robot).double()
    link = body.link[body.pairs]
    assert bool(((link[:, 0] - link[:, 1]).abs() >= 2).all())  # adjacent links never checked
    q = robot.sample(3000, torch.Generator().manual_seed(7), dtype=torch.float64)
    _, per = self_collision_distance(body(q), body.radii, body.pairs, per_pair=True)
    share = (per < 0).double().mean(0)
    assert float(share.max()) < 0.95  # no pair that (nearly) always overlaps is kept
    assert 0.0 < float((per.amin(-1) < 0).double().mean()) < 0.6


def test_panda_distance_matches_coal_on_a_mixed_scene():
    import coal

    robot = load_robot("panda")
    body = body_spheres(robot).double()
    R = rotation_from_quaternion([0.1, 0.3, -0.2, 0.9])
    prims = [
        Sphere((0.4, 0.1, 0.5), 0.08),
        Box((0.5, -0.2, 0.3), (0.1, 0.2, 0.05), R),
        Cylinder((0.3, 0.3, 0.4), 0.05, 0.2, R),
    ]
    scene = Scene.from_primitives(prims)
    q = robot.sample(8, torch.Generator().manual_seed(3), dtype=torch.float64)
    c = body(q)
    _, per = body_obstacle_distance(c, body.radii, scene, per_sphere=True)

    def tf(Rm, p):
        t = coal.Transform3s()
        t.setRotation(np.asarray(Rm, dtype=float))
        t.setTranslation(np.asarray(p, dtype=float))
        return t

    shapes = [
        (coal.Sphere(0.08), np.eye(3), prims[0].centre),
        (coal.Box(0.2, 0.4, 0.1), R, prims[1].centre),
        (coal.Cylinder(0.05, 0.4), R, prims[2].centre),
    ]
    req = coal.DistanceRequest()
    req.gjk_tolerance = req.epa_tolerance = 1e-12
    req.gjk_max_iterations = req.epa_max_iterations = 1000
    for n in range(8):
        for m in range(body.num_spheres):
            me = coal.Capsule(float(body.radii[m]), 0.0)  # GJK/EPA: exact for a ball against any of them
            ref = min(
                max(
                    coal.distance(g, tf(np.eye(3), c[n, m]), s, tf(Rm, p), req, coal.DistanceResult())
                    for g in (coal.Sphere(float(body.radii[m])), me)
                )
                for s, Rm, p in shapes
            )
            assert abs(float(per[n, m]) - ref) < 1e-6


def test_register_robot_with_spheres(tmp_path):
    panda = load_robot("panda")
    name = "sphered_panda"
    try:
        mine = kinlearn.register_robot(
            name,
            panda.urdf_path,
            ee_frame="panda_hand_tcp",
            spheres=ROBOTS / "panda" / "panda_spherized.urdf",
        )
        body, ref = body_spheres(mine), body_spheres(panda)
        assert torch.equal(body.local, ref.local) and torch.equal(body.pairs, ref.pairs)
    finally:
        kinlearn.body.unregister_robot(name)
    bad = tmp_path / "bad.urdf"
    text = (ROBOTS / "panda" / "panda_spherized.urdf").read_text()
    bad.write_text(
        text.replace('name="panda_finger_joint1" type="fixed"', 'name="panda_finger_joint1" type="prismatic"')
    )
    with pytest.raises(RobotDescriptionError, match="panda_finger_joint1"):
        urdf_spheres(panda, bad)


def test_a_body_read_from_a_urdf_carries_its_models_joint_limits_within_the_robots():
    """The ur5's sphere file (the benchmarks' UR5) limits every joint to ±π, kinlearn's ur5 turns ±2π: its
    bodies carry ±π; the panda's file is a little wider than kinlearn's panda, so its body keeps the
    robot's, and its outer limits are the file's; the iiwa14's spheres come with no model, and keep the
    robot's."""
    ur5 = load_robot("ur5")
    assert (ur5.upper > 6.0).sum() == 5  # kinlearn's ur5: ±2π but the elbow
    for name in ("spherized", "gripper"):
        lo, hi = body_spheres(ur5, sphere_set=name).limits
        np.testing.assert_allclose(np.stack([lo, hi]), [[-np.pi] * 6, [np.pi] * 6], atol=1e-7)
    for name in ("panda", "iiwa14"):
        robot = load_robot(name)
        lo, hi = body_spheres(robot).limits
        assert np.array_equal(lo, robot.lower) and np.array_equal(hi, robot.upper)
    # the widest box a plan may use: the robot's and its model's together (the panda's file, MoveIt's panda)
    panda = load_robot("panda")
    body = body_spheres(panda)
    lo, hi = body.outer_limits
    np.testing.assert_allclose(hi, [2.9671, 1.8326, 2.9671, 0.0873, 2.9671, 3.8223, 2.9671])
    np.testing.assert_allclose(lo, [-2.9671, -1.8326, -2.9671, -3.1416, -2.9671, -0.0873, -2.9671])
    within, band = np.zeros((1, 7)), np.full((1, 7), 0.1)
    within[0, 3], band[0, 3] = -1.0, -1.0
    band[0, 6] = 2.93  # beyond the robot's 2.8973
    assert np.array_equal(body.joint_box(within, within)[1][0], panda.upper)
    assert np.array_equal(body.joint_box(within, band)[1][0], hi)
    for name in ("spherized", "gripper"):
        b = body_spheres(ur5, sphere_set=name)
        assert np.array_equal(b.outer_limits[0], ur5.lower) and np.array_equal(b.outer_limits[1], ur5.upper)


def test_body_limits_that_leave_no_range_and_unreadable_urdf_limits_are_refused():
    """A body's limits must leave every joint a range within the robot's; a sphere URDF's limit must be
    numbers. ``joint_box``: the body's limits where both ends lie within them, else its outer limits (the
    ur5's: the robot's)."""
    from kinlearn.collision.body import BodySpheres, urdf_limits

    ur5 = load_robot("ur5")
    body = body_spheres(ur5)
    spheres = np.column_stack([body.link.numpy(), body.local.numpy(), body.radii.numpy()])
    lo = ur5.lower.copy()
    with pytest.raises(RobotDescriptionError, match="range within its own"):
        BodySpheres(ur5, spheres, body.pairs.numpy(), limits=(lo, lo))
    with pytest.raises(RobotDescriptionError, match="two arrays of 6 values"):
        BodySpheres(ur5, spheres, body.pairs.numpy(), limits=(lo[:5], ur5.upper))
    urdf = b"""<robot name="r"><link name="a"/><link name="b"/>
      <joint name="shoulder_pan_joint" type="revolute"><parent link="a"/><child link="b"/>
      <axis xyz="0 0 1"/><limit lower="low" upper="1.0" effort="1" velocity="1"/></joint></robot>"""
    with pytest.raises(RobotDescriptionError, match="unreadable limit"):
        urdf_limits(ur5, urdf)
    inside, beyond = np.zeros((1, 6)), np.full((1, 6), 4.0)
    assert np.allclose(body.joint_box(inside, inside)[1], np.pi)
    assert np.array_equal(body.joint_box(inside, beyond)[1][0], ur5.upper)
