"""Scenes: validation of obstacles (typed errors), batching, padding masks and .npz files."""

import math

import numpy as np
import pytest
import torch

from kinlearn.collision import Scene
from kinlearn.errors import DatasetError, ObstacleError
from kinlearn.io import save_npz

SPHERES = torch.tensor([[0.5, 0.0, 0.4, 0.1], [0.3, -0.2, 0.6, 0.05]])
BOXES = torch.tensor([[0.6, 0.2, 0.1, 0.2, 0.1, 0.1]])


@pytest.mark.parametrize(
    "spheres, match",
    [
        (torch.tensor([[0.5, 0.0, 0.4, 0.0]]), "radius"),
        (torch.tensor([[0.5, 0.0, 0.4, -0.1]]), "radius"),
        (torch.tensor([[math.nan, 0.0, 0.4, 0.1]]), "NaN"),
        (torch.tensor([[0.5, math.inf, 0.4, 0.1]]), "NaN"),
        (torch.tensor([[0.5, 0.0, 0.4]]), "shape"),
        (torch.tensor([0.5, 0.0, 0.4, 0.1]), "shape"),
        (torch.tensor([[1, 2, 3, 4]], dtype=torch.bool), "floating-point"),
        ("spheres", "numbers"),
    ],
)
def test_bad_spheres(spheres, match):
    with pytest.raises(ObstacleError, match=match):
        Scene.from_spheres(spheres)


@pytest.mark.parametrize(
    "boxes, match",
    [
        (torch.tensor([[0.5, 0.0, 0.4, 0.1, 0.0, 0.1]]), "half extent"),
        (torch.tensor([[0.5, 0.0, 0.4, 0.1, -0.2, 0.1]]), "half extent"),
        (torch.tensor([[0.5, 0.0, math.nan, 0.1, 0.1, 0.1]]), "NaN"),
        (torch.tensor([[0.5, 0.0, 0.4, 0.1]]), "shape"),
    ],
)
def test_bad_boxes(boxes, match):
    with pytest.raises(ObstacleError, match=match):
        Scene(boxes=boxes)


def test_bad_floor_masks_and_batches():
    with pytest.raises(ObstacleError, match="floor"):
        Scene(SPHERES, floor=math.nan)
    with pytest.raises(ObstacleError, match="bool"):
        Scene(SPHERES, sphere_mask=torch.ones(2))
    with pytest.raises(ObstacleError, match="one entry per obstacle"):
        Scene(SPHERES, sphere_mask=torch.ones(3, dtype=torch.bool))
    with pytest.raises(ObstacleError, match="broadcast"):
        Scene(SPHERES.expand(3, 2, 4), BOXES.expand(2, 1, 6))
    with pytest.raises(ObstacleError):
        Scene(SPHERES)[0]  # an unbatched scene has no batch dimension to index
    assert isinstance(ObstacleError("x"), ValueError)


def test_valid_scenes_and_padding():
    s = Scene(SPHERES, BOXES, floor=0.0)
    assert s.batch_shape == () and s.num_spheres == 2 and s.num_boxes == 1 and s.dtype == torch.float32
    assert Scene().num_spheres == 0 and Scene().num_boxes == 0
    # Lists and arrays are accepted; float64 tensors keep their dtype; boxes follow the spheres' dtype.
    assert Scene.from_spheres([[0.5, 0.0, 0.4, 0.1]]).num_spheres == 1
    s64 = Scene(SPHERES.double(), BOXES)
    assert s64.boxes.dtype == torch.float64
    # A masked (padding) entry is not validated: its radius may be anything.
    padded = Scene(
        torch.tensor([[0.5, 0.0, 0.4, 0.1], [0.0, 0.0, 0.0, -1.0]]), sphere_mask=torch.tensor([True, False])
    )
    assert padded.num_spheres == 2
    # stack pads to the largest counts with masks, unstack drops the padding.
    a, b = Scene(SPHERES, BOXES, floor=0.0), Scene(SPHERES[:1], floor=0.1)
    st = Scene.stack([a, b])
    assert st.batch_shape == (2,) and st.spheres.shape == (2, 2, 4) and st.boxes.shape == (2, 1, 15)
    assert st.sphere_mask.tolist() == [[True, True], [True, False]] and st.box_mask.tolist() == [
        [True],
        [False],
    ]
    back = st.unstack()
    assert (
        torch.equal(back[1].spheres, SPHERES[:1])
        and back[1].num_boxes == 0
        and float(back[1].floor) == pytest.approx(0.1)
    )
    assert torch.equal(st[0].spheres, SPHERES)
    with pytest.raises(ObstacleError, match="floor"):
        Scene.stack([a, Scene(SPHERES)])
    # unsqueeze inserts a batch dimension; expand broadcasts.
    assert st.unsqueeze(-1).batch_shape == (2, 1)
    assert st.expand(3, 2).batch_shape == (3, 2)
    assert Scene(SPHERES).to(torch.float64).spheres.dtype == torch.float64


def test_save_load_round_trip(tmp_path):
    st = Scene.stack(
        [Scene(SPHERES.double(), BOXES.double(), floor=0.0), Scene(SPHERES[:1].double(), floor=-0.1)]
    )
    path = st.save(tmp_path / "scene.npz", robot="iiwa14")
    back = Scene.load(path, robot="iiwa14")
    assert torch.equal(back.spheres, st.spheres) and torch.equal(back.boxes, st.boxes)
    assert torch.equal(back.floor, st.floor) and torch.equal(back.sphere_mask, st.sphere_mask)
    assert torch.equal(back.box_mask, st.box_mask)
    plain = Scene(SPHERES)
    again = Scene.load(plain.save(tmp_path / "plain.npz"), dtype=torch.float32)
    assert again.floor is None and again.sphere_mask is None and torch.equal(again.spheres, SPHERES)
    assert not list(tmp_path.glob(".*.tmp"))  # written atomically, nothing left behind


def test_load_refuses_bad_files(tmp_path):
    with pytest.raises(DatasetError, match="no dataset file"):
        Scene.load(tmp_path / "missing.npz")
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(b"not a zip file")
    with pytest.raises(DatasetError, match="not a readable"):
        Scene.load(corrupt)
    other = save_npz(
        tmp_path / "other.npz", kind="babbling", robot="iiwa14", config={}, arrays={"x": np.zeros(3)}
    )
    with pytest.raises(DatasetError, match="expected 'scene'"):
        Scene.load(other)
    old = save_npz(
        tmp_path / "old.npz",
        kind="scene",
        robot="",
        config={"scene_format": 99},
        arrays=Scene(SPHERES).arrays(),
    )
    with pytest.raises(DatasetError, match="scene format 99"):
        Scene.load(old)
    bad = Scene(SPHERES).arrays()
    bad["spheres"][0, 3] = -1.0
    bad_path = save_npz(tmp_path / "bad.npz", kind="scene", robot="", config={"scene_format": 1}, arrays=bad)
    with pytest.raises(DatasetError, match="invalid obstacles"):
        Scene.load(bad_path)
    with pytest.raises(DatasetError, match="robot"):
        Scene.load(Scene(SPHERES).save(tmp_path / "for_panda.npz", robot="panda"), robot="iiwa14")


def test_as_scene_takes_scenes_or_spheres_and_checks_the_batch():
    from kinlearn.collision.scene import as_scene
    from kinlearn.errors import ShapeError

    one = as_scene([[0.5, 0.0, 0.6, 0.1]])
    assert tuple(one.batch_shape) == () and one.num_spheres == 1
    assert as_scene(one) is one
    per = as_scene(torch.ones(3, 2, 4), batch=(3,))
    assert tuple(per.batch_shape) == (3,)
    assert as_scene(one, batch=(3,)) is one  # one scene for every problem
    with pytest.raises(ShapeError, match="one scene for all"):
        as_scene(torch.ones(2, 2, 4), batch=(3,))
    for bad in ("spheres", None, torch.ones(2, 3), torch.ones(2, 4, dtype=torch.bool), [[1, 2], [3]]):
        with pytest.raises(ObstacleError):
            as_scene(bad)


def test_a_list_of_balls_is_converted_once_by_its_content():
    """Planning query after query among the same balls converts them (and packs them) once; other balls,
    another scene; a malformed list raises every time; a large array is converted each time, the same."""
    from kinlearn.collision.scene import _REMEMBERED_FLOATS, as_scene

    balls = [[0.5, 0.0, 0.6, 0.1], [0.2, 0.3, 0.4, 0.05]]
    one = as_scene(balls)
    assert as_scene([list(b) for b in balls]) is one
    assert as_scene(np.array(balls)) is one
    assert as_scene(torch.tensor(balls, dtype=torch.float64)) is one
    moved = as_scene([[0.5, 0.0, 0.6, 0.1], [0.2, 0.3, 0.4, 0.06]])
    assert moved is not one and float(moved.spheres[1, 3]) == 0.06
    assert torch.equal(one.spheres, torch.tensor(balls, dtype=torch.float64))
    for _ in range(2):
        with pytest.raises(ObstacleError, match="radius"):
            as_scene([[0.5, 0.0, 0.6, -0.1]])
    many = np.random.default_rng(0).uniform(0.1, 0.5, (_REMEMBERED_FLOATS // 4 + 1, 4))
    a, b = as_scene(many), as_scene(many)
    assert a is not b and torch.equal(a.spheres, b.spheres)
