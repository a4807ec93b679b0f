"""The iiwa14's collision spheres: placement against Pinocchio's link frames, the data file, the base
cover, the self-collision pairs and the travel bound used by the dense path check."""

import json
import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import torch

from kinlearn import kinematics, load_robot
from kinlearn.collision import body_spheres, cover_cylinder, sphere_sets
from kinlearn.collision.body import SPHERE_FILE, _axis_distances
from kinlearn.errors import ConfigError, NonFiniteError, RobotDescriptionError, ShapeError


@pytest.fixture(scope="module")
def q64(robot):
    return robot.sample(200, torch.Generator().manual_seed(3), dtype=torch.float64)


def _pinocchio_link_frames(robot, q: torch.Tensor) -> np.ndarray:
    """(N, dof + 1, 4, 4): Pinocchio's placement of iiwa_link_0 … iiwa_link_7, parsed independently."""
    pk = kinematics(robot, "pinocchio")
    model, data = pk.model, pk.data
    ids = [model.getFrameId(f"iiwa_link_{k}", pin.FrameType.BODY) for k in range(robot.dof + 1)]
    out = np.empty((q.shape[0], robot.dof + 1, 4, 4))
    for i, qi in enumerate(q.numpy()):
        pin.forwardKinematics(model, data, pk._q(qi))
        pin.updateFramePlacements(model, data)
        out[i] = np.stack([data.oMf[f].homogeneous for f in ids])
    return out


@pytest.mark.parametrize("dense", [False, True])
def test_centres_match_pinocchio_link_frames(robot, q64, dense):
    body = body_spheres(robot, dense=dense).double()
    T = _pinocchio_link_frames(robot, q64[:50])
    link, local = body.link.numpy(), body.local.numpy()
    Tl = T[:, link]
    ref = np.einsum("nmij,mj->nmi", Tl[..., :3, :3], local) + Tl[..., :3, 3]
    got = body(q64[:50])
    assert got.shape == (50, body.num_spheres, 3)
    assert np.abs(got.numpy() - ref).max() <= 1e-12


def test_link_poses_match_pinocchio(robot, q64):
    T = kinematics(robot, "fast").link_poses(q64[:20].reshape(4, 5, 7))
    assert T.shape == (4, 5, robot.dof + 1, 4, 4)
    ref = _pinocchio_link_frames(robot, q64[:20])
    assert np.abs(T.reshape(20, -1, 4, 4).numpy() - ref).max() <= 1e-12


def test_sphere_counts_and_reference_numbers(robot):
    sparse, dense = body_spheres(robot), body_spheres(robot, dense=True)
    # Drake's 12 arm spheres, link by link (Drake's iiwa14_spheres_collision.urdf), plus 6 covering the base cylinder.
    assert np.bincount(sparse.link.numpy(), minlength=8).tolist() == [6, 1, 2, 3, 2, 2, 1, 1]
    assert sparse.num_spheres == 18 and dense.num_spheres == 46
    assert np.bincount(dense.link.numpy(), minlength=8).tolist() == [4, 5, 9, 9, 6, 9, 3, 1]
    link1 = sparse.link == 1
    assert torch.allclose(
        sparse.local[link1], torch.tensor([[0.0, -0.03344534434, 0.1974815417]], dtype=torch.float64)
    )
    assert float(sparse.radii[link1]) == 0.07959901601
    assert float(sparse.radii[sparse.link == 7]) == 0.05285650291
    arm_only = body_spheres(robot, base=False)
    assert arm_only.num_spheres == 12 and bool((arm_only.link > 0).all())


def test_data_file_documents_its_sources(robot):
    model = sphere_sets(robot)
    for key in ("sparse", "dense"):
        assert "RobotLocomotion/drake" in model["sets"][key]["source"]
    assert model["base_cylinder"]["radius"] == 0.139 and model["base_cylinder"]["length"] == 0.17


def test_centres_batched_dtype_and_gradient(robot):
    body = body_spheres(robot)
    q32 = robot.sample((3, 4), torch.Generator().manual_seed(0))
    c = body(q32)
    assert c.shape == (3, 4, 18, 3) and c.dtype == torch.float32
    assert torch.allclose(c, body(q32.double()).float(), atol=1e-5)
    # Base spheres never move; link-1 spheres keep their height.
    base = body.link == 0
    assert torch.equal(c[..., base, :], body.local[base].float().expand(3, 4, -1, 3))
    body64 = body.double()
    q = robot.sample(2, torch.Generator().manual_seed(1), dtype=torch.float64).requires_grad_(True)
    assert torch.autograd.gradcheck(lambda x: body64(x), (q,))


def test_bad_joints_and_unknown_robot(robot):
    body = body_spheres(robot)
    with pytest.raises(ShapeError):
        body(torch.zeros(6))
    with pytest.raises(NonFiniteError):
        body(torch.full((7,), math.nan))
    myarm = (
        Path(__file__).resolve().parents[1] / "examples" / "data" / "myarm.urdf"
    )  # a URDF alone, no spheres
    with pytest.raises(RobotDescriptionError, match="no collision sphere model"):
        body_spheres(load_robot(myarm, "tool0"))


def test_base_cover_contains_the_cylinder(robot):
    model = sphere_sets(robot)
    cyl = model["base_cylinder"]
    cover = np.asarray(model["base_cylinder_cover"]["spheres"])[:, 1:]
    again = cover_cylinder(tuple(cyl["centre"]), cyl["radius"], cyl["length"])
    assert np.allclose(again, cover, rtol=0, atol=1e-12)  # the file rounds to 1e-12 m
    # Points of the solid cylinder, its rim circles and its faces, each inside some sphere.
    rng = np.random.default_rng(0)
    R, h, c = cyl["radius"], cyl["length"] / 2, np.asarray(cyl["centre"])
    th = rng.uniform(0, 2 * np.pi, 20000)
    rad = R * np.sqrt(rng.uniform(0, 1, 20000))
    rad[:5000] = R  # on the side
    z = rng.uniform(-h, h, 20000)
    z[5000:7000] = h
    z[7000:9000] = -h
    z[9000:10000] = np.sign(z[9000:10000]) * h  # rim circles
    rad[9000:10000] = R
    pts = np.stack([rad * np.cos(th), rad * np.sin(th), z], 1) + c
    inside = np.linalg.norm(pts[:, None, :] - cover[None, :, :3], axis=2) <= cover[None, :, 3] + 1e-12
    assert inside.any(axis=1).all()
    # How far the cover reaches out of the cylinder (documented: at most 4.4 cm).
    g = rng.normal(size=(4000, 3))
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    surf = (cover[:, None, :3] + cover[:, None, 3:] * g[None]).reshape(-1, 3) - c
    out = np.hypot(np.maximum(np.hypot(surf[:, 0], surf[:, 1]) - R, 0), np.maximum(np.abs(surf[:, 2]) - h, 0))
    assert 0.03 < out.max() <= 0.044
    with pytest.raises(ConfigError):
        cover_cylinder((0, 0, 0), 0.1, 0.2, ring=6, ring_radius=0.2)


@pytest.mark.parametrize("dense", [False, True])
def test_self_collision_pairs(robot, dense):
    body = body_spheres(robot, dense=dense).double()
    link = body.link
    i, j = body.pairs[:, 0], body.pairs[:, 1]
    gap = (link[i] - link[j]).abs()
    assert bool((gap >= 2).all())  # never adjacent links
    assert not bool(((link[i] == 5) & (link[j] == 7)).any())  # Drake's wrist filter group
    # Every other non-adjacent pair is checked.
    m = body.num_spheres
    expected = sum(
        1
        for a in range(m)
        for b in range(a + 1, m)
        if abs(int(link[a]) - int(link[b])) >= 2 and {int(link[a]), int(link[b])} != {5, 7}
    )
    assert len(body.pairs) == expected
    # The kept pairs are apart at the zero configuration and rarely overlap over the joint range.
    c0 = body(torch.zeros(7, dtype=torch.float64))
    r = body.radii
    d0 = (c0[i] - c0[j]).norm(dim=-1) - r[i] - r[j]
    assert float(d0.min()) > 0.02
    q = robot.sample(4000, torch.Generator().manual_seed(5), dtype=torch.float64)
    c = body(q)
    overlap = ((c[:, i] - c[:, j]).norm(dim=-1) - r[i] - r[j] < 0).double().mean(0)
    assert float(overlap.max()) <= 0.005
    # The excluded wrist pairs would overlap often (sparse set: always, at the zero configuration).
    w5, w7 = torch.nonzero(link == 5).flatten(), torch.nonzero(link == 7).flatten()
    dw = (c[:, w5, None] - c[:, None, w7]).norm(dim=-1) - r[w5, None] - r[None, w7]
    assert float((dw.amin((1, 2)) < 0).double().mean()) > (0.5 if not dense else 0.03)


def test_floor_mask_and_data_file_name(robot):
    body = body_spheres(robot)
    assert torch.equal(body.floor_mask, body.link > 0)
    # a link-1 sphere reaching below the base plane, which no joint raises (the first axis is vertical),
    # rests on the mount: the floor spares it, as the base; one above the plane and any further out do not
    from kinlearn.collision.body import floor_applies

    local = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -0.15], [0.0, 0.0, 0.0], [0.0, 0.0, -0.15]])
    mask = floor_applies(robot, np.array([0, 1, 1, 2]), local, np.array([0.1, 0.02, 0.05, 0.02]))
    assert mask.tolist() == [False, False, True, True]
    raw = json.loads((robot.urdf_path.parent / SPHERE_FILE).read_text())
    assert raw["robot"] == "iiwa14"


def test_lever_bound_holds(robot):
    """No sphere moves further than Σ_j lever[m, j] |Δθ_j| along a straight joint-space step."""
    body = body_spheres(robot, dense=True).double()
    gen = torch.Generator().manual_seed(11)
    q0 = robot.sample(500, gen, dtype=torch.float64)
    dq = (torch.rand(500, 7, generator=gen, dtype=torch.float64) - 0.5) * 0.4
    # Arc length of every sphere along the step, by fine subdivision.
    s = torch.linspace(0, 1, 65, dtype=torch.float64)
    c = body(q0[:, None, :] + s[None, :, None] * dq[:, None, :])  # (500, 65, M, 3)
    arc = (c[:, 1:] - c[:, :-1]).norm(dim=-1).sum(1)  # (500, M)
    bound = dq.abs() @ body.lever.T  # (500, M)
    assert bool((arc <= bound + 1e-12).all())
    moves = bound > 1e-9  # (spheres on their joint's axis, and the base's, never move)
    assert float((arc[moves] / bound[moves]).max()) > 0.5  # and it is not wildly loose


@pytest.mark.parametrize("name", ["iiwa14", "panda", "ur5"])
def test_pair_distance_changes_no_faster_than_the_axis_bound(name):
    """A self-collision pair's distance changes along a straight joint-space step by at most
    Σ_j |Δθ_j| min(lever of its upper sphere, axis distance of its lower one) over the joints between
    their links: the bound the compiled verdict spends budgets by. Tight where it matters: a pair whose
    lower sphere sits on the axes between them keeps its distance."""
    from kinlearn.collision import kernel

    arm = load_robot(name)
    body = body_spheres(arm).double()
    kb = kernel.KernelBody(body)
    pairs = body.pairs.numpy()
    lever = torch.as_tensor(kb._item_lever(pairs))  # with the body's axis distances (_axis_distances)
    gen = torch.Generator().manual_seed(4)
    q0 = arm.sample(300, gen, dtype=torch.float64)
    dq = (torch.rand(300, arm.dof, generator=gen, dtype=torch.float64) - 0.5) * 2.0
    s = torch.linspace(0, 1, 33, dtype=torch.float64)
    c = body(q0[:, None, :] + s[None, :, None] * dq[:, None, :])  # (300, 33, M, 3)
    i, j = torch.as_tensor(pairs[:, 0]), torch.as_tensor(pairs[:, 1])
    dist = (c[..., i, :] - c[..., j, :]).norm(dim=-1)  # (300, 33, P)
    change = (dist[:, 1:] - dist[:, :-1]).abs().sum(1)  # total variation along the step
    bound = dq.abs() @ lever.T
    assert bool((change <= bound + 1e-12).all())
    full = dq.abs() @ torch.maximum(body.lever[i], body.lever[j]).T  # the upper sphere's lever alone
    assert float(bound.sum()) < float(full.sum())  # and tighter than the lever alone


@pytest.mark.parametrize("name", ["iiwa14", "panda", "ur5"])
def test_axis_distances_bound_every_sampled_configuration(name):
    """No sphere is ever farther from the axis of a joint after its link than _axis_distances says."""
    arm = load_robot(name)
    body = body_spheres(arm).double()
    bound = _axis_distances(arm, body.link.numpy(), body.local.numpy())
    F = kinematics(arm, "fast").F
    q = arm.sample(200, torch.Generator().manual_seed(9), dtype=torch.float64).numpy()
    c = body(torch.as_tensor(q)).numpy()
    link = body.link.numpy()
    worst = -np.inf
    for n in range(len(q)):
        T = np.eye(4)
        for j in range(arm.dof):
            A = T @ F[j]  # joint j's frame: its axis is z through the origin
            v = c[n] - A[:3, 3]
            d = np.linalg.norm(v - (v @ A[:3, 2])[:, None] * A[:3, 2], axis=1)
            before = link <= j
            worst = max(worst, float((d[before] - bound[before, j]).max()))
            Z = np.eye(4)
            Z[:2, :2] = [[math.cos(q[n, j]), -math.sin(q[n, j])], [math.sin(q[n, j]), math.cos(q[n, j])]]
            T = A @ Z
    assert worst <= 1e-12


@pytest.mark.parametrize("name", ["iiwa14", "panda", "ur5"])
def test_reach_bounds_every_configuration(name):
    """No sphere of a planning body (the ur5's with its gripper) is ever farther from the base's origin than
    ``reach``: 20,000 configurations across the limits come within 0.35 m of it and never past it."""
    from kinlearn.collision import planning_body

    body = planning_body(load_robot(name))
    q = torch.as_tensor(
        np.random.default_rng(0).uniform(body.robot.lower, body.robot.upper, (20000, body.robot.dof))
    )
    far = float((body(q).norm(dim=-1) + body.radii).max())
    assert far <= body.reach < far + 0.35
