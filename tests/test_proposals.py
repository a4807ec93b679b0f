"""The compiled proposals held to the obstacle-aware TM in torch: the knots of every candidate, and the
candidate paths the planner checks (the line, the network's paths, the reversed problem's walked
backwards, clipped, halved, ordered by length)."""

from __future__ import annotations

import numpy as np
import torch
from conftest import state_pairs

from kinlearn.collision import Scene
from kinlearn.collision.geometry import Box, Cylinder, Sphere
from kinlearn.collision.kernel import KernelScene
from kinlearn.models.obstacle_path import ObstaclePathConfig, ObstaclePathModel, scene_primitives
from kinlearn.planning.proposals import CompiledObstacleModel


def _model(robot, activation="silu") -> ObstaclePathModel:
    torch.manual_seed(0)
    config = ObstaclePathConfig.for_robot(
        robot, hidden=(32, 32), encoder=(16, 24), candidates=4, activation=activation
    )
    tm = ObstaclePathModel(config)
    with torch.no_grad():  # weights of a trained size, so the candidates differ visibly
        for p in tm.trunk[-1].parameters():
            p.normal_(0.0, 0.1)
        tm.in_mean.normal_(0.0, 0.3)  # a standardisation to fold in
        tm.in_std.uniform_(0.5, 2.0)
    return tm.eval()


def _scene() -> Scene:
    turn = np.array([[0.8, -0.6, 0.0], [0.6, 0.8, 0.0], [0.0, 0.0, 1.0]])
    return Scene.from_primitives(
        [
            Sphere([0.5, 0.0, 0.4], 0.1),
            Box([0.6, 0.1, 0.2], [0.2, 0.1, 0.05], turn),
            Cylinder([0.3, -0.3, 0.5], 0.05, 0.2, turn),
        ],
        floor=0.0,
    )


def test_compiled_knots_match_torch(robot):
    """Both activations, scenes with padding inside the rows (a masked sphere before the boxes) and
    without primitives: the knots agree with torch's float32 forward pass within 1e-4 rad."""
    for activation in ("silu", "tanh"):
        tm = _model(robot, activation)
        net = CompiledObstacleModel(tm)
        s0, sT = state_pairs(robot, 3, seed=1)
        mask = torch.ones(3, 2, dtype=torch.bool)
        mask[0, 1] = False
        padded = Scene(
            torch.tensor([[[0.5, 0.0, 0.4, 0.1], [0.3, 0.3, 0.2, 0.05]]]).repeat(3, 1, 1),
            torch.tensor([[[0.6, 0.0, 0.1, 0.2, 0.3, 0.1]]]).repeat(3, 1, 1),
            floor=torch.zeros(3),
            sphere_mask=mask,
        )
        for scene in (padded, _scene().expand(3), Scene().expand(3)):
            rows, m, floor = scene_primitives(scene, 3)
            with torch.no_grad():
                ref = tm(s0, sT, rows, m, floor).double().numpy()
            a = [x.double().numpy() for x in (s0[:, :7], s0[:, 7:], sT[:, :7], sT[:, 7:])]
            out = net(*a, rows.double().numpy(), m.numpy(), floor.double().numpy())
            assert out.shape == ref.shape
            assert np.abs(out - ref).max() < 1e-4, activation


def test_proposals_are_the_line_the_paths_and_the_reversed_paths(robot):
    """The candidates the planner checks, from one call: the straight joint line first (to the bit), then
    the network's paths for the problem, then its paths for the problem the other way round walked
    backwards, knots clipped to the box; halving puts a knot midway along every segment; the order is by
    joint-space length, shortest first."""
    tm = _model(robot)
    net = CompiledObstacleModel(tm)
    s0, sT = state_pairs(robot, 1, seed=3)
    ks = KernelScene(_scene())
    rows, floor = ks.model_rows(), ks.floor
    a0, e0, aT, eT = (x[0].double().numpy() for x in (s0[:, :7], s0[:, 7:], sT[:, :7], sT[:, 7:]))
    lo, hi = np.minimum(a0, aT) - 0.05, np.maximum(a0, aT) + 0.05  # a narrow box: some knots clipped
    paths, order = net.proposals(a0, e0, aT, eT, rows, floor, lo, hi, False)
    C = tm.config.candidates
    assert paths.shape == (2 * C + 1, tm.config.steps + 1, 7)
    f = net.fractions[:, None]
    assert np.array_equal(paths[0, 1:-1], a0 + f * (aT - a0))
    assert (paths[:, 0] == a0).all() and (paths[:, -1] == aT).all()
    prims = (torch.from_numpy(rows)[None].float(), torch.ones(1, len(rows), dtype=torch.bool))
    with torch.no_grad():
        ahead = tm(s0, sT, *prims, torch.from_numpy(floor)[None].float()).double().numpy()[0]
        back = tm(sT, s0, *prims, torch.from_numpy(floor)[None].float()).double().numpy()[0]
    assert np.abs(paths[1 : C + 1, 1:-1] - np.clip(ahead, lo, hi)).max() < 1e-4
    assert np.abs(paths[C + 1 :, 1:-1] - np.clip(back[:, ::-1], lo, hi)).max() < 1e-4
    assert ((ahead < lo) | (ahead > hi)).any()  # the box did clip
    length = np.linalg.norm(np.diff(paths, axis=1), axis=-1).sum(-1)
    assert np.array_equal(order, np.argsort(length, kind="stable"))
    halved, order2 = net.proposals(a0, e0, aT, eT, rows, floor, lo, hi, True)
    assert np.array_equal(halved[:, ::2], paths)
    assert np.allclose(halved[:, 1::2], 0.5 * (paths[:, :-1] + paths[:, 1:]), atol=1e-15)
    assert np.array_equal(order2, order)


def test_first_free_is_the_proposals_checked_in_their_order(robot):
    """A plan's stage 1 in one call: where the straight line collides, the same candidates and order as
    :meth:`proposals` and the first free one by the kernel's own ``first_free`` (−1 when none is); where
    the line is free, the line (every candidate a copy: the network is not run); NaN joints raise."""
    import pytest

    from kinlearn.collision.body import body_spheres
    from kinlearn.collision.kernel import KernelBody, first_free
    from kinlearn.data.problem import positions
    from kinlearn.errors import NonFiniteError

    net = CompiledObstacleModel(_model(robot))
    body = KernelBody(body_spheres(robot).double())
    lo, hi = np.asarray(robot.lower, dtype=np.float64), np.asarray(robot.upper, dtype=np.float64)
    rng = np.random.default_rng(0)
    seen = {"line": 0, "network": 0, "none": 0}
    far = KernelScene(Scene.from_spheres([[5.0, 5.0, 5.0, 0.1]], floor=None))
    for _ in range(16):
        q = lo + (hi - lo) * rng.uniform(0.3, 0.7, size=(2, robot.dof))
        e = positions(robot, q)
        mid = positions(robot, q.mean(0, keepdims=True))[0]  # a ball on the line's hand path
        for ks in (far, KernelScene(Scene.from_spheres([[*mid, 0.04]], floor=None))):
            for halve in (False, True):
                paths, order, k = net.first_free(q[0], e[0], q[1], e[1], lo, hi, halve, body, ks, 0.01)
                if first_free(body, paths[:1], ks) == 0:  # the line is free: it is the plan
                    seen["line"] += 1
                    assert k == 0 and (paths == paths[:1]).all()
                    continue
                rows, floor = ks.model_rows(), ks.floor
                ref, ref_order = net.proposals(q[0], e[0], q[1], e[1], rows, floor, lo, hi, halve)
                assert np.array_equal(paths, ref) and np.array_equal(order, ref_order)
                assert k == first_free(body, ref, ks, ref_order[ref_order != 0])
                seen["network" if k > 0 else "none"] += 1
    assert seen["line"] and seen["network"] and seen["none"]
    bad = q[0].copy()
    bad[0] = np.nan
    with pytest.raises(NonFiniteError):
        net.first_free(bad, e[0], q[1], e[1], lo, hi, False, body, KernelScene(_scene()), 0.01)


def test_the_network_reads_only_what_the_arm_can_reach():
    """A primitive whose bounding ball lies beyond the body's reach is left out of the network's rows, so a
    plan among a scene is the same with a box 3 m behind the base added; one within reach is kept."""
    import warnings
    from pathlib import Path

    import kinlearn
    from kinlearn.collision.scene import as_scene
    from kinlearn.data.problems import ProblemSet

    data = Path(__file__).resolve().parents[1] / "benchmarks" / "data" / "scene_problems_panda.npz"
    ps = ProblemSet.load(data, robot="panda")
    planner = kinlearn.Planner.default("panda")
    far = Box([-3.2, 0.0, 0.2], [0.2, 0.2, 0.2])
    near = Box([-0.9, 0.0, 0.2], [0.2, 0.2, 0.2])
    reach = planner._np_body.reach
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for i in range(4):
            start, goal, scene = ps.problem(i)
            prims = list(as_scene(scene).primitives())
            a = planner.plan(start, goal, obstacles=Scene.from_primitives(prims), refine_steps=0)
            b = planner.plan(start, goal, obstacles=Scene.from_primitives([*prims, far]), refine_steps=0)
            assert torch.equal(a.joints, b.joints) and a.stage == b.stage
    packed = KernelScene(Scene.from_primitives([*prims, far, near]))
    assert packed.model_rows().shape[0] == len(prims) + 1  # the floor is no row
    rows = packed.model_rows(reach)
    assert rows.shape[0] == len(prims)
    assert (
        np.isclose(rows[:, :3], near.centre).all(1).any()
        and not np.isclose(rows[:, :3], far.centre).all(1).any()
    )
