"""Point-cloud obstacles: readers and their typed errors, checks of the points, the camera pose, cleaning,
and the distance grid's promise (free under the grid is free under the points), compiled and torch alike."""

import math

import numpy as np
import pytest
import torch

from kinlearn.collision import Scene, body_obstacle_distance, check_path
from kinlearn.collision.cloud import (
    EXACT,
    Cleaning,
    PointCloud,
    clean_points,
    points_in_base,
    read_points,
)
from kinlearn.collision.cloud_render import DepthCamera, surface_points
from kinlearn.errors import DatasetError, ObstacleError, PointCloudError, PointCloudFileError

RNG = np.random.default_rng(7)
POINTS = RNG.random((200, 3)) * 0.4 + (0.3, -0.2, 0.1)


# -------------------------------------------------------------------------------------------------
# Readers
# -------------------------------------------------------------------------------------------------


def _pcd_header(n: int, data: str, fields="x y z", size="4 4 4", type_="F F F", count="1 1 1") -> bytes:
    return (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
        f"FIELDS {fields}\nSIZE {size}\nTYPE {type_}\nCOUNT {count}\n"
        f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
    ).encode()


def test_readers_read_each_format(tmp_path):
    from plyfile import PlyData, PlyElement

    pts = POINTS.astype(np.float32).astype(np.float64)
    np.save(tmp_path / "a.npy", pts)
    rec = np.zeros(len(pts), dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("intensity", "f4")])
    rec["x"], rec["y"], rec["z"] = pts.T
    for text in (True, False):
        PlyData([PlyElement.describe(rec, "vertex")], text=text).write(str(tmp_path / f"a{text}.ply"))
    (tmp_path / "ascii.pcd").write_bytes(
        _pcd_header(len(pts), "ascii") + "\n".join(" ".join(f"{v:.9g}" for v in p) for p in pts).encode()
    )
    (tmp_path / "binary.pcd").write_bytes(
        _pcd_header(len(pts), "binary", "x y z rgb", "4 4 4 4", "F F F U", "1 1 1 1")
        + np.stack([rec["x"], rec["y"], rec["z"], np.zeros(len(pts), "f4")], 1).astype("f4").tobytes()
    )
    for name in ("a.npy", "aTrue.ply", "aFalse.ply", "ascii.pcd", "binary.pcd"):
        got = read_points(tmp_path / name)
        np.testing.assert_allclose(got, pts, rtol=0, atol=1e-6, err_msg=name)


@pytest.mark.parametrize(
    "name, content, match",
    [
        ("bad.npy", b"not a numpy file", "not a readable"),
        (
            "bad.ply",
            b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nend_header\n1\n",
            "malformed|PLY",
        ),
        ("bad2.ply", b"hello", "PLY"),
        ("nodata.pcd", b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\n", "DATA"),
        ("short.pcd", _pcd_header(3, "ascii") + b"0 0 0\n1 1 1\n", "3 points"),
        ("trunc.pcd", _pcd_header(10, "binary") + b"\x00" * 12, "bytes"),
        ("noz.pcd", _pcd_header(1, "ascii", "x y w") + b"0 0 0\n", "no field z"),
        ("comp.pcd", _pcd_header(1, "binary_compressed") + b"\x00" * 12, "binary_compressed"),
        ("junk.pcd", b"GARBAGE 1 2 3\n", "not a PCD header"),
        ("points.xyz", b"0 0 0\n", "not '.xyz'"),
    ],
)
def test_each_reader_refuses_a_bad_file_with_its_typed_error(tmp_path, name, content, match):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(PointCloudFileError, match=match):
        read_points(path)
    with pytest.raises(PointCloudFileError):  # through the scene's front door too
        Scene.from_points(path)


def test_a_npy_of_the_wrong_shape_and_a_missing_file(tmp_path):
    np.save(tmp_path / "wide.npy", np.zeros((5, 4)))
    with pytest.raises(PointCloudFileError, match=r"\(N, 3\)"):
        read_points(tmp_path / "wide.npy")
    with pytest.raises(PointCloudFileError, match="no such"):
        read_points(tmp_path / "missing.pcd")
    assert issubclass(PointCloudFileError, DatasetError) and issubclass(PointCloudError, ObstacleError)


# -------------------------------------------------------------------------------------------------
# Points, pose, cleaning
# -------------------------------------------------------------------------------------------------


def test_bad_points_are_refused_by_name():
    with pytest.raises(PointCloudError, match="NaN"):
        Scene.from_points(np.vstack([POINTS, [np.nan, 0, 0]]))
    assert Scene.from_points(np.vstack([POINTS, [np.nan, 0, 0]]), drop_nonfinite=True).cloud.num_points == 200
    with pytest.raises(PointCloudError, match=r"shape \(N, 3\)"):
        Scene.from_points(np.zeros((4, 2)))
    with pytest.raises(PointCloudError, match="reshape"):
        Scene.from_points(np.zeros((4, 5, 3)))
    with pytest.raises(PointCloudError, match="no point"):
        Scene.from_points(np.zeros((0, 3)))
    with pytest.raises(PointCloudError, match="millimetres"):
        Scene.from_points(POINTS * 1000)
    with pytest.raises(PointCloudError, match="real numbers"):
        Scene.from_points(np.array([["a", "b", "c"]]))
    with pytest.raises(PointCloudError, match="radius"):
        Scene.from_points(POINTS, radius=-0.01)
    with pytest.raises(PointCloudError, match="crop"):
        Scene.from_points(np.array([[0.0, 0.0, 0.0], [15.0, 15.0, 15.0]]), resolution=0.002)


def test_a_camera_pose_moves_points_into_the_base_frame():
    yaw = math.pi / 2
    T = np.eye(4)
    T[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    T[:3, 3] = (1.0, 2.0, 3.0)
    q = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    a = points_in_base(POINTS, T)
    np.testing.assert_allclose(a, points_in_base(POINTS, ((1.0, 2.0, 3.0), q)), atol=1e-12)
    np.testing.assert_allclose(a, points_in_base(POINTS, [1.0, 2.0, 3.0, *q]), atol=1e-12)
    np.testing.assert_allclose(a[0], (1.0 - POINTS[0, 1], 2.0 + POINTS[0, 0], 3.0 + POINTS[0, 2]), atol=1e-12)
    with pytest.raises(PointCloudError, match="frame"):
        points_in_base(POINTS, np.eye(3))
    bad = np.eye(4)
    bad[0, 0] = 2.0
    with pytest.raises(PointCloudError, match="orthonormal"):
        points_in_base(POINTS, bad)


def test_cleaning_down_samples_and_drops_outliers():
    wall = np.stack(np.meshgrid(np.arange(0, 0.2, 0.005), np.arange(0, 0.2, 0.005)), -1).reshape(-1, 2)
    wall = np.column_stack([wall, np.full(len(wall), 0.5)])
    stray = np.array([[0.1, 0.1, 0.9]])
    pts = np.vstack([wall, stray])
    voxel = clean_points(pts, 0.01, Cleaning(voxel=0.02))
    assert 100 <= len(voxel) <= 121 + 1  # 10 × 10 cells of the wall (and the stray point)
    for how in ("radius", "statistical"):
        kept = clean_points(pts, 0.01, Cleaning(outliers=how, outlier_radius=0.03))
        assert not (kept[:, 2] > 0.8).any(), how  # the stray point
        # the wall kept (the statistical rule also drops a perfect grid's four corners, its farthest points)
        assert len(kept) >= len(wall) - (4 if how == "statistical" else 0), how
    with pytest.raises(PointCloudError, match="outliers"):
        Cleaning(outliers="median")
    with pytest.raises(PointCloudError, match="voxel"):
        Cleaning(voxel=0.0)
    with pytest.raises(PointCloudError, match="no point is left"):
        clean_points(stray, 0.01, Cleaning(reach=0.5))


def test_self_filtering_drops_the_robots_own_points(robot, body):
    q = torch.as_tensor((robot.lower + robot.upper) / 2)
    centres = body(q[None])[0].numpy()
    radii = body.radii.numpy()
    on_arm = centres[5] + np.array([radii[5] * 0.5, 0.0, 0.0])  # inside a body sphere
    wall = np.array([[0.9, y, z] for y in np.arange(-0.3, 0.3, 0.02) for z in np.arange(0.2, 0.8, 0.02)])
    pts = np.vstack([wall, on_arm])
    kept = clean_points(pts, 0.01, None, self_filter=(body, q.numpy()))
    assert len(kept) == len(wall)
    assert np.isin(kept[:, 0], 0.9).all()
    # unfiltered, the point makes the robot's configuration collide (torch check, the grid's twin)
    scene = Scene.from_points(pts)
    assert not bool(check_path(body, q[None].expand(2, -1), scene).collision_free)
    filtered = Scene.from_points(pts, self_filter=(body, q.numpy()))
    assert bool(check_path(body, q[None].expand(2, -1), filtered).collision_free)
    with pytest.raises(PointCloudError, match="joints"):
        Scene.from_points(pts, self_filter=(body, q.numpy()[:3]))
    # at several configurations (where it stands, and a goal vouched for): the points on each body go
    other = q.clone()
    other[1] += 1.0  # the shoulder turned: the hand far from where it was
    on_other = body(other[None])[0, -1].numpy()
    both = np.vstack([wall, on_arm, on_other])
    assert len(clean_points(both, 0.01, None, self_filter=(body, q.numpy()))) == len(wall) + 1
    kept = clean_points(both, 0.01, None, self_filter=(body, torch.stack([q, other]).numpy()))
    assert len(kept) == len(wall)
    # a vouched configuration's body drops the points within its own margin (the obstacle's surface beside
    # a goal stays)
    c, r = body(other[None])[0, -1].numpy(), float(body.radii[-1])
    beside = c + np.array([0.0, 0.0, r + 0.01 + 0.01])  # its ball 1 cm from the sphere
    near = np.vstack([wall, beside])
    # where the robot stands: kept at the default 5 mm, dropped within a 2 cm shell
    assert len(clean_points(near, 0.01, None, self_filter=(body, other.numpy()))) == len(wall) + 1
    shell = clean_points(near, 0.01, Cleaning(self_margin=0.02), self_filter=(body, other.numpy()))
    assert len(shell) == len(wall)
    stack = torch.stack([q, other]).numpy()
    assert len(clean_points(near, 0.01, None, self_filter=(body, stack))) == len(wall) + 1  # 4 mm: kept
    wide = Cleaning(vouch_margin=0.02)
    assert len(clean_points(near, 0.01, wide, self_filter=(body, stack))) == len(wall)
    with pytest.raises(PointCloudError, match="vouch_margin"):
        Cleaning(vouch_margin=-0.001)
    with pytest.raises(PointCloudError, match="joints"):
        Scene.from_points(pts, self_filter=(body, np.zeros((2, 3))))


# -------------------------------------------------------------------------------------------------
# The grid
# -------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_free_under_the_grid_is_free_under_the_points(seed):
    rng = np.random.default_rng(seed)
    radius, resolution = [(0.01, 0.01), (0.0, 0.02), (0.015, 0.007)][seed]
    # surfaces (the points a camera gives) and a loose scatter
    face = rng.random((3000, 3)) * (0.6, 0.6, 0.0) + (0.1, -0.3, 0.4)
    post = np.column_stack(
        [0.05 * np.cos(t := rng.random(1000) * 6.3) + 0.5, 0.05 * np.sin(t), rng.random(1000)]
    )
    pts = np.vstack([face, post, rng.random((200, 3)) * 1.2 - 0.3])
    cloud = PointCloud(pts, radius, resolution)
    centres = rng.random((20000, 3)) * 1.8 - 0.6
    r = rng.random(20000) * 0.2  # body spheres and links' bounding balls
    bound = cloud.distance(centres) - r
    nearest = np.concatenate(  # brute force, in chunks (the whole broadcast holds gigabytes)
        [np.sqrt(((c[:, None] - pts[None]) ** 2).sum(-1).min(1)) for c in np.array_split(centres, 40)]
    )
    true = nearest - radius - r
    assert (bound <= true + 1e-12).all()  # the grid never reports more room than there is
    free = bound > 0
    assert free.any() and (~free).any()
    assert (true[free] > 0).all()
    # not vacuous: inside the points' bounding box the bound is within a cell's diagonal of the truth
    inside = ((centres >= pts.min(0)) & (centres <= pts.max(0))).all(1)
    assert (true[inside] - bound[inside]).max() <= 2 * math.sqrt(3) * resolution + 1e-9
    # the torch twin gives the same numbers, and a gradient
    c = torch.as_tensor(centres, dtype=torch.float64).requires_grad_(True)
    twin = cloud.distance_torch(c)
    np.testing.assert_allclose(twin.detach().numpy(), cloud.distance(centres), rtol=0, atol=1e-12)
    twin.sum().backward()
    assert torch.isfinite(c.grad).all()
    # a body sphere's query is exact wherever the sphere comes within EXACT of the balls, a lower bound
    # beyond, never below the grid's bound, and so the points' own verdict at any margin below EXACT
    sphere = cloud.distance(centres, r) - r
    near = true <= EXACT
    assert near.sum() > 100
    np.testing.assert_allclose(sphere[near], true[near], rtol=0, atol=1e-12)
    assert (sphere <= true + 1e-12).all() and (sphere >= bound - 1e-12).all()
    for margin in (0.0, 0.004, 0.0099):
        np.testing.assert_array_equal(sphere > margin, true > margin)
    assert ((sphere > 0) & (bound <= 0)).sum() > 100  # spheres the grid alone could not clear
    # its torch twin: the same numbers, and a gradient
    c2 = torch.as_tensor(centres, dtype=torch.float64).requires_grad_(True)
    twin = cloud.distance_torch(c2, torch.as_tensor(r)) - torch.as_tensor(r)
    np.testing.assert_allclose(twin.detach().numpy(), sphere, rtol=0, atol=1e-12)
    twin.sum().backward()
    assert torch.isfinite(c2.grad).all()
    for bad in (-r, np.full_like(r, np.nan)):
        with pytest.raises(PointCloudError, match="radii"):
            cloud.distance(centres, bad)


def test_points_and_primitives_mix_in_one_scene(body, robot):
    box = torch.tensor([[0.6, 0.0, 0.3, 0.05, 0.05, 0.05]])
    scene = Scene.from_points(POINTS, primitives=Scene(boxes=box), floor=0.0)
    assert scene.num_boxes == 1 and scene.cloud.num_points == 200 and float(scene.floor) == 0.0
    assert "points=200" in repr(scene)
    q = torch.as_tensor(robot.sample(64, torch.Generator().manual_seed(0), dtype=torch.float64))
    c = body(q)
    both = body_obstacle_distance(c, body.radii, scene)
    prims = body_obstacle_distance(c, body.radii, Scene(boxes=box, floor=0.0))
    cloud = (scene.cloud.distance_torch(c) - body.radii).amin(-1)
    torch.testing.assert_close(both, torch.minimum(prims, cloud))
    batched = Scene.stack([scene, scene])
    assert batched.cloud is scene.cloud and batched.unstack()[1].cloud is scene.cloud
    with pytest.raises(ObstacleError, match="one point cloud"):
        Scene.stack([scene, Scene.from_points(POINTS, floor=0.0)])
    with pytest.raises(ObstacleError, match="MoveIt"):
        scene.to_moveit()


def test_a_scene_with_points_saves_and_loads(tmp_path):
    scene = Scene.from_points(POINTS, radius=0.02, resolution=0.015, floor=0.0)
    back = Scene.load(scene.save(tmp_path / "s.npz"))
    np.testing.assert_array_equal(back.cloud.points, scene.cloud.points)
    assert (back.cloud.radius, back.cloud.resolution) == (0.02, 0.015) and float(back.floor) == 0.0


def test_rendered_clouds_cover_the_primitives():
    box = Scene(boxes=torch.tensor([[0.6, 0.0, 0.3, 0.1, 0.2, 0.3]]), floor=0.0)
    pts = surface_points(box, spacing=0.01, noise=0.0)
    h = np.array([0.1, 0.2, 0.3])
    on_face = np.isclose(np.abs(pts - (0.6, 0.0, 0.3)), h, atol=1e-9).any(1)
    assert on_face.all() and len(pts) > 2 * (20 * 60 + 10 * 60 + 10 * 20)
    cam = DepthCamera(position=(0.0, 0.0, 0.3), target=(0.6, 0.0, 0.3), width=64, height=48, noise=0.0)
    seen = cam.points(box)
    np.testing.assert_allclose(seen[:, 0], 0.5, atol=1e-9)  # only the face towards the camera
    assert len(seen) > 100


def test_what_a_camera_sees_of_a_scene():
    box = Scene(boxes=torch.tensor([[0.6, 0.0, 0.3, 0.1, 0.2, 0.3]]), floor=0.0)
    cam = DepthCamera(position=(0.0, 0.0, 0.3), target=(0.6, 0.0, 0.3), width=64, height=48, noise=0.0)
    assert cam.sees(box, cam.points(box)).all()  # every point it returns
    pts = surface_points(box, spacing=0.02, noise=0.0)
    in_view = np.abs(pts[:, 2] - 0.3) < 0.25  # its image spans ±0.29 m vertically at the face
    front, back = np.isclose(pts[:, 0], 0.5) & in_view, np.isclose(pts[:, 0], 0.7)
    seen = cam.sees(box, pts)
    assert seen[front].all() and not seen[back].any()  # the face towards it, not the one behind
    assert not seen[np.isclose(pts[:, 0], 0.5) & (np.abs(pts[:, 2] - 0.3) > 0.295)].any()  # out of its image
    assert not cam.sees(box, [[-0.5, 0.0, 0.3], [0.6, 3.0, 0.3]]).any()  # behind the camera; out of its image
    assert cam.sees(box, [[0.3, 0.0, 0.3]]).all()  # a point in front of the face, in free space
    # a ball between the camera and the face hides the face's middle
    ball = np.array([[0.25, 0.0, 0.3, 0.05]])
    middle = [[0.5, 0.0, 0.3]]
    assert cam.sees(box, middle).all() and not cam.sees(box, middle, spheres=ball).any()
    t = cam.first_hits(box, np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]))
    np.testing.assert_allclose(t[0], 0.5, atol=1e-12)
    assert np.isinf(t[1]) and np.isinf(t[2])  # nothing that way; the floor


def test_a_cameras_points_in_its_own_frame_and_their_shadows():
    box = Scene(boxes=torch.tensor([[0.6, 0.0, 0.3, 0.1, 0.2, 0.3]]))
    cam = DepthCamera(position=(0.0, 0.3, 0.5), target=(0.6, 0.0, 0.3), width=48, height=36, noise=0.0)
    T = cam.pose()
    seen = cam.points(box)
    in_camera = (seen - T[:3, 3]) @ T[:3, :3]
    assert (in_camera[:, 2] > 0).all()  # in front of the camera: its z looks forward
    scene = Scene.from_points(in_camera, frame=T)
    np.testing.assert_allclose(scene.cloud.points, seen, atol=1e-12)
    shadowed = Scene.from_points(in_camera, frame=T, shadow=0.05, resolution=0.01)
    assert shadowed.cloud.num_points == 6 * len(seen)
    behind = shadowed.cloud.points[len(seen) :]
    assert (np.linalg.norm(behind - T[:3, 3], axis=1) > np.linalg.norm(seen - T[:3, 3], axis=1).min()).all()
    with pytest.raises(PointCloudError, match="camera's pose"):
        Scene.from_points(seen, shadow=0.05)


def test_two_cameras_views_fuse_into_one_cloud(tmp_path):
    # a box seen from two sides: each camera sees its own face, the fused cloud both, in the base frame
    box = Scene(boxes=torch.tensor([[0.6, 0.0, 0.3, 0.1, 0.2, 0.3]]))
    cams = [
        DepthCamera(position=(0.0, 0.0, 0.3), target=(0.6, 0.0, 0.3), width=48, height=36, noise=0.0),
        DepthCamera(position=(0.6, 0.8, 0.3), target=(0.6, 0.0, 0.3), width=48, height=36, noise=0.0),
    ]
    seen = [c.points(box) for c in cams]
    poses = [c.pose() for c in cams]
    views = [(p - T[:3, 3]) @ T[:3, :3] for p, T in zip(seen, poses, strict=True)]
    np.save(tmp_path / "b.npy", views[1])
    fused = Scene.from_points([views[0], tmp_path / "b.npy"], frame=poses).cloud.points
    np.testing.assert_allclose(fused, np.concatenate(seen), atol=1e-12)
    assert np.isclose(fused[:, 0], 0.5).sum() == len(seen[0])  # the face towards the first camera
    assert np.isclose(fused[:, 1], 0.2).sum() == len(seen[1])  # and the second's
    # views already in the base frame take no pose, or None among the poses
    np.testing.assert_allclose(Scene.from_points(seen).cloud.points, fused, atol=1e-12)
    mixed = Scene.from_points([seen[0], views[1]], frame=[None, poses[1]]).cloud.points
    np.testing.assert_allclose(mixed, fused, atol=1e-12)
    with pytest.raises(PointCloudError, match="2 views of points take a list of 2 camera poses"):
        Scene.from_points(views, frame=poses[0])
    with pytest.raises(PointCloudError, match="2 views"):
        Scene.from_points(views, frame=poses[:1])
    with pytest.raises(PointCloudError, match="view 1's points must have shape"):
        Scene.from_points([views[0], views[1][:, :2]], frame=poses)
    with pytest.raises(PointCloudError, match="view 1: frame must be"):
        Scene.from_points(views, frame=[poses[0], np.eye(3)])
    with pytest.raises(PointCloudError, match="one camera's view"):
        Scene.from_points(views, frame=poses, shadow=0.1)


def test_what_the_arm_hides_from_the_camera_is_occupied(robot, body):
    q = torch.as_tensor((robot.lower + robot.upper) / 2)
    with torch.no_grad():
        centres, radii = body(q[None])[0].numpy(), body.radii.numpy()
    arm = np.column_stack([centres, radii])
    target = centres[len(centres) // 2]
    wall = Scene(boxes=torch.tensor([[target[0] + 0.5, target[1], target[2], 0.02, 0.6, 0.6]]))
    cam = DepthCamera(position=tuple(target - (0.8, 0.0, 0.0)), target=tuple(target), width=64, height=48)
    T = cam.pose()
    seen = cam.points(wall, spheres=arm)
    in_camera = (seen - T[:3, 3]) @ T[:3, :3]
    scene = Scene.from_points(in_camera, frame=T, shadow=0.4, self_filter=(body, q.numpy()))
    # the arm stands free where it was seen...
    assert bool(check_path(body, q[None].expand(2, -1), scene).collision_free)
    # ...and the space it hides, between it and the wall, is occupied
    ray = target - T[:3, 3]
    ray /= np.linalg.norm(ray)
    hidden = target + ray * (radii[len(centres) // 2] + 0.2)
    assert scene.cloud.distance(hidden[None])[0] < 0
    bare = cam.points(wall)
    without_arm = Scene.from_points((bare - T[:3, 3]) @ T[:3, :3], frame=T, shadow=0.4)
    assert without_arm.cloud.distance(hidden[None])[0] > 0.1  # free were the arm not there
