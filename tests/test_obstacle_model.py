"""The obstacle-aware TM: shapes, the set encoder, checkpoints (its compiled twin: tests/test_proposals.py)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from conftest import state_pairs

from kinlearn.collision import Scene
from kinlearn.errors import CheckpointError, ConfigError
from kinlearn.models.obstacle_path import (
    ObstaclePathConfig,
    ObstaclePathModel,
    load_obstacle_model,
    save_obstacle_model,
    scene_primitives,
)


def _model(robot, **fields) -> ObstaclePathModel:
    torch.manual_seed(0)
    tm = ObstaclePathModel(ObstaclePathConfig.for_robot(robot, hidden=(32, 32), encoder=(16, 24), **fields))
    with torch.no_grad():  # weights of a trained size, so the candidates differ visibly
        for p in tm.trunk[-1].parameters():
            p.normal_(0.0, 0.1)
    return tm.eval()


def _scene(n):
    spheres = torch.tensor([[[0.5, 0.0, 0.4, 0.1], [0.3, 0.3, 0.2, 0.05]]]).repeat(n, 1, 1)
    boxes = torch.tensor([[[0.6, 0.0, 0.1, 0.2, 0.3, 0.1]]]).repeat(n, 1, 1)
    mask = torch.ones(n, 2, dtype=torch.bool)
    mask[0, 1] = False
    return Scene(spheres, boxes, floor=torch.zeros(n), sphere_mask=mask)


def test_candidates_start_and_end_at_the_problem(robot):
    tm = _model(robot, candidates=5, modes=4)
    s0, sT = state_pairs(robot, 3)
    mid = tm(s0, sT, *scene_primitives(_scene(3), 3))
    assert mid.shape == (3, 5, 10, 7)
    # The sine modes vanish at t = 0 and t = T: extending the basis to the ends gives the endpoints.
    t = torch.tensor([0.0, 1.0])
    ends = torch.sin(torch.pi * t[:, None] * torch.arange(1, 5))
    assert ends.abs().max() < 1e-6
    # Candidates differ (else the planner had one candidate).
    assert (mid[:, 0] - mid[:, 1]).abs().max() > 1e-3


def test_padding_and_order_of_primitives_do_not_matter(robot):
    tm = _model(robot)
    s0, sT = state_pairs(robot, 1)
    a = Scene(torch.tensor([[0.5, 0.0, 0.4, 0.1], [0.3, 0.3, 0.2, 0.05]]))
    b = Scene(torch.tensor([[0.3, 0.3, 0.2, 0.05], [0.5, 0.0, 0.4, 0.1]]))
    padded = Scene(
        torch.tensor([[[0.5, 0.0, 0.4, 0.1], [0.3, 0.3, 0.2, 0.05], [9.0, 9.0, 9.0, 1.0]]]),
        sphere_mask=torch.tensor([[True, True, False]]),
    )
    outs = [tm(s0, sT, *scene_primitives(sc, 1)) for sc in (a, b, padded)]
    assert torch.allclose(outs[0], outs[1], atol=1e-6)
    assert torch.allclose(outs[0], outs[2], atol=1e-6)
    # ... while the obstacles do matter.
    moved = Scene(torch.tensor([[0.5, 0.2, 0.4, 0.1], [0.3, 0.3, 0.2, 0.05]]))
    assert (tm(s0, sT, *scene_primitives(moved, 1)) - outs[0]).abs().max() > 1e-5


def test_empty_scene_gives_a_finite_plan(robot):
    tm = _model(robot)
    s0, sT = state_pairs(robot, 2)
    out = tm(s0, sT, *scene_primitives(Scene(), 2))
    assert torch.isfinite(out).all()


def test_checkpoint_round_trip_and_wrong_robot(robot, tmp_path):
    tm = _model(robot)
    save_obstacle_model(tm, tmp_path / "tm_obstacles.pt")
    back = load_obstacle_model(tmp_path / "tm_obstacles.pt", robot="iiwa14")
    s0, sT = state_pairs(robot, 2)
    prims = scene_primitives(_scene(2), 2)
    assert torch.equal(back(s0, sT, *prims), tm(s0, sT, *prims))
    with pytest.raises(CheckpointError):
        load_obstacle_model(tmp_path / "tm_obstacles.pt", robot="panda")


def test_bad_config(robot):
    with pytest.raises(ConfigError):
        ObstaclePathConfig.for_robot(robot, candidates=0)
    with pytest.raises(ConfigError):
        ObstaclePathConfig.for_robot(robot, encoder=())
    with pytest.raises(ConfigError):
        ObstaclePathConfig(dof=7)  # no limits
    with pytest.raises(ConfigError):
        scene_primitives(_scene(3), 2)  # a scene per problem, but for 3 problems


def _rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _mixed_scene(turn: float = 0.6) -> Scene:
    from kinlearn.collision.geometry import Box, Cylinder, Sphere

    tilt = _rot_z(turn) @ np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    return Scene.from_primitives(
        [
            Sphere((0.5, 0.1, 0.4), 0.08),
            Box((0.55, -0.2, 0.3), (0.3, 0.01, 0.2), _rot_z(turn).ravel()),
            Cylinder((0.3, 0.4, 0.5), 0.03, 0.25, tilt.ravel()),
        ],
        floor=0.0,
    )


def test_shape_rows_tell_which_way_a_primitive_lies():
    """The extent tensor is one per shape however its frame is written (axes flipped, a cylinder turned
    about its own axis) and tells apart two plates the bounding box cannot: turned +45° and −45°."""
    from kinlearn.collision.geometry import Box, Cylinder, shape_tensor

    def rows(prims):
        return scene_primitives(Scene.from_primitives(prims), 1, torch.float64)[0][0]

    R = _rot_z(0.4)
    flipped = R @ np.diag([-1.0, -1.0, 1.0])
    a, b = (
        rows([Box((0, 0, 0.5), (0.3, 0.01, 0.2), R.ravel())]),
        rows([Box((0, 0, 0.5), (0.3, 0.01, 0.2), flipped.ravel())]),
    )
    assert torch.allclose(a, b, atol=1e-12)
    c = rows([Cylinder((0, 0, 0.5), 0.05, 0.2, R.ravel())])
    d = rows([Cylinder((0, 0, 0.5), 0.05, 0.2, np.eye(3).ravel())])
    assert torch.allclose(c, d, atol=1e-12)  # turned about its own (z) axis
    assert c[0, 13] == 1.0 and c[0, 6] == 0.0 and a[0, 13] == 0.0
    plus, minus = (
        rows([Box((0, 0, 0.5), (0.3, 0.01, 0.2), _rot_z(np.pi / 4).ravel())]),
        rows([Box((0, 0, 0.5), (0.3, 0.01, 0.2), _rot_z(-np.pi / 4).ravel())]),
    )
    assert torch.allclose(plus[0, :7], minus[0, :7], atol=1e-12)  # the same bounding box
    assert abs(float(plus[0, 10] - minus[0, 10])) > 0.2  # Lxy: opposite diagonals
    # A box's tensor's eigenvalues are its half extents.
    box = Box((0, 0, 0), (0.3, 0.01, 0.2), _rot_z(0.7).ravel())
    L = shape_tensor(Box, torch.tensor(box.row(), dtype=torch.float64))
    M = torch.tensor([[L[0], L[3], L[4]], [L[3], L[1], L[5]], [L[4], L[5], L[2]]])
    assert torch.allclose(torch.linalg.eigvalsh(M), torch.tensor([0.01, 0.2, 0.3], dtype=torch.float64))


def test_the_kernels_rows_are_scene_primitives_rows_to_the_bit():
    from kinlearn.collision.kernel import KernelScene

    scene = _mixed_scene()
    rows = scene_primitives(scene, 1, torch.float64)[0][0].numpy()
    assert rows.shape == (3, 14)
    assert np.array_equal(KernelScene(scene).model_rows(), rows)


def test_shape_model_sees_turns_and_old_files_read_boxes(robot, tmp_path):
    """A model reading extent tensors sees a box turn; a checkpoint written before the choice existed (no
    ``primitives`` in its config) reads bounding boxes, as it was trained to."""
    tm = _model(robot)
    assert tm.config.primitives == "shape" and tm.row_columns == 14
    s0, sT = state_pairs(robot, 3, seed=2)
    rows, mask, floor = scene_primitives(_mixed_scene().expand(3), 3)
    with torch.no_grad():
        ref = tm(s0, sT, rows, mask, floor).double().numpy()
        turned = tm(s0, sT, *scene_primitives(_mixed_scene(-0.6).expand(3), 3)).double().numpy()
    assert np.abs(turned - ref).max() > 1e-5  # it sees the turn
    old = ObstaclePathConfig.for_robot(robot, hidden=(8,), encoder=(8,)).to_dict()
    del old["primitives"]
    assert ObstaclePathConfig.from_dict(old).primitives == "aabb"
    with pytest.raises(ConfigError, match="primitives"):
        ObstaclePathConfig.for_robot(robot, primitives="mesh")


def test_a_bad_record_of_training_families_is_refused(robot, tmp_path):
    """A checkpoint whose families are not a list of names is a CheckpointError, not a model that
    says it saw something it did not; a good record survives saving and export."""
    from kinlearn.io import load_checkpoint, save_checkpoint
    from kinlearn.models.obstacle_path import export_obstacle_model

    tm = _model(robot)
    assert tm.body is None
    tm.families, tm.body = ("cage", "bin"), "gripper"
    path = save_obstacle_model(tm, tmp_path / "tm_obstacles.pt")
    assert load_obstacle_model(path).families == ("cage", "bin")
    exported = load_obstacle_model(export_obstacle_model(path, tmp_path / "exported.pt"))
    assert exported.families == ("cage", "bin") and exported.body == "gripper"
    payload = load_checkpoint(path, kind=ObstaclePathModel.kind)
    for extra, why in (({"families": "cage"}, "training families"), ({"body": 3}, "training body")):
        save_checkpoint(
            tmp_path / "bad.pt",
            kind=ObstaclePathModel.kind,
            robot=payload["robot"],
            config=payload["config"],
            state_dict=payload["state_dict"],
            extra=extra,
        )
        with pytest.raises(CheckpointError, match=why):
            load_obstacle_model(tmp_path / "bad.pt")


def test_a_feature_that_never_varied_in_training_is_held_at_its_mean(robot):
    """Every training scene had a floor at z = 0, so the floor flag and height never varied: the network
    (torch and compiled alike) plans a scene without a floor, or with one at another height, as it plans
    the floor it knows. Unheld, a missing floor put the flag 1,000 standard deviations out."""
    from kinlearn.planning.proposals import CompiledObstacleModel

    tm = _model(robot, candidates=3)
    s0, sT = state_pairs(robot, 4, seed=2)
    rows, mask, _ = scene_primitives(_scene(4), 4)
    floors = torch.tensor([[1.0, 0.0]]).repeat(4, 1)
    with torch.no_grad():
        tm.fit_normalization(s0, sT, rows, mask, floors)  # the floor constant, as in training
    in_scale, _ = tm.input_scales
    assert torch.isinf(in_scale[-2:]).all() and torch.isfinite(in_scale[:-2]).all()
    net = CompiledObstacleModel(tm)
    dof = tm.config.dof
    a = [x.double().numpy() for x in (s0[:, :dof], s0[:, dof:], sT[:, :dof], sT[:, dof:])]
    with torch.no_grad():
        ref = tm(s0, sT, rows, mask, floors)
        compiled = net(*a, rows.double().numpy(), mask.numpy(), floors.double().numpy())
        for other in ([0.0, 0.0], [1.0, -0.4], [1.0, 0.3]):  # no floor; a floor lower, higher
            f = torch.tensor([other]).repeat(4, 1)
            assert torch.equal(tm(s0, sT, rows, mask, f), ref)
            assert np.array_equal(net(*a, rows.double().numpy(), mask.numpy(), f.double().numpy()), compiled)
    # a feature that varied in training still counts
    s1 = sT.clone()
    s1[:, 0] += 0.5
    with torch.no_grad():
        assert not torch.equal(tm(s0, s1, rows, mask, floors), ref)


def test_a_primitive_feature_that_never_varied_in_training_is_held_at_its_mean(robot):
    """Boxes turned about z only (every family but clutter) leave a box's tilt terms (Lxz, Lyz of its
    extent tensor) at 0 in training: a tilted box (clutter's, a lid at 45°) is read with those terms at
    their mean, in torch and compiled alike, while its bounding box and other terms still count.
    Unheld, a network trained without clutter read its tilted boxes tens to hundreds of standard
    deviations out (the ur5's clutter left out: 75% in fixed time, 100% held)."""
    from kinlearn.collision.geometry import Box
    from kinlearn.planning.proposals import CompiledObstacleModel

    tm = _model(robot, candidates=3)
    s0, sT = state_pairs(robot, 6, seed=3)
    yawed = [
        Box(
            (0.3 + 0.1 * k, 0.1 * k - 0.2, 0.2 + 0.05 * k),
            (0.2 - 0.02 * k, 0.1, 0.05 + 0.01 * k),
            _yaw(0.4 * k),
        )
        for k in range(6)
    ]
    rows, mask, floor = scene_primitives(Scene.from_primitives(yawed, floor=0.0), 6)
    with torch.no_grad():
        tm.fit_normalization(s0, sT, rows, mask, floor)
    _, prim_scale = tm.input_scales
    assert torch.isinf(prim_scale[11:13]).all() and torch.isfinite(prim_scale[:11]).all()  # Lxy varied

    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    lid = Box((0.6, 0.0, 0.7), (0.35, 0.35, 0.02), (c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c))  # 45° about y
    tilted, tmask, tfloor = scene_primitives(Scene.from_primitives([lid], floor=0.0), 6)
    assert tilted[0, 0, 11].abs() > 0.05  # Lxz: 0.06 m, 60 spreads of the floor MIN_STD out
    flat = tilted.clone()
    flat[..., 11:13] = 0.0  # the training mean
    net = CompiledObstacleModel(tm)
    dof = tm.config.dof
    a = [x.double().numpy() for x in (s0[:, :dof], s0[:, dof:], sT[:, :dof], sT[:, dof:])]
    with torch.no_grad():
        ref = tm(s0, sT, flat, tmask, tfloor)
        assert torch.equal(tm(s0, sT, tilted, tmask, tfloor), ref)
        compiled = net(*a, tilted.double().numpy(), tmask.numpy(), tfloor.double().numpy())
        assert np.array_equal(
            compiled, net(*a, flat.double().numpy(), tmask.numpy(), tfloor.double().numpy())
        )
        np.testing.assert_allclose(compiled, ref.double().numpy(), atol=1e-4)
        # the lid's bounding box still counts: a lid lying flat reads otherwise
        level = Box((0.6, 0.0, 0.7), (0.35, 0.35, 0.02))
        assert not torch.equal(
            tm(s0, sT, *scene_primitives(Scene.from_primitives([level], floor=0.0), 6)), ref
        )


def _yaw(angle: float) -> tuple[float, ...]:
    c, s = np.cos(angle), np.sin(angle)
    return (c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)


def test_the_shipped_network_plans_a_scene_without_a_floor():
    """A panda problem of the held-out scene families with its floor left out (as a MoveIt scene or a list
    of balls comes): the network's candidates are what they are with the floor, and clear it alone."""
    from pathlib import Path

    import kinlearn
    from kinlearn.collision.geometry import Plane
    from kinlearn.collision.scene import as_scene
    from kinlearn.data.problems import ProblemSet

    data = Path(__file__).resolve().parents[1] / "benchmarks" / "data" / "scene_problems_panda.npz"
    ps = ProblemSet.load(data, robot="panda")
    alone = kinlearn.Planner.default("panda", retreat=False)
    cleared = with_floor = 0
    for i in range(6):
        start, goal, scene = ps.problem(i)
        bare = Scene.from_primitives([p for p in as_scene(scene).primitives() if not isinstance(p, Plane)])
        assert bare.floor is None
        a = alone.plan(start, goal, obstacles=scene, refine_steps=0)
        b = alone.plan(start, goal, obstacles=bare, refine_steps=0)
        if a.stage == "learned":  # the floor only narrows the free space: what clears with it clears without
            assert b.stage == "learned" and bool(b.collision_free) and bool(b.success)
        with_floor += a.stage == "learned"
        cleared += b.stage == "learned" and bool(b.success)
    assert cleared >= with_floor >= 1
