"""Motor babbling: limits, step bound, FK consistency, determinism, datasets on disk."""

import numpy as np
import pytest
import torch

from kinlearn import ConfigError, DatasetError, ShapeError, kinematics, load_robot
from kinlearn.body.state import StateLayout
from kinlearn.data.babbling import BabblingConfig, Transitions, babble, load_transitions, save_transitions
from kinlearn.io import save_npz


@pytest.fixture(scope="module", params=["iiwa14", "panda", "ur5"])
def data(request):
    return babble(BabblingConfig(robot=request.param, walkers=64, steps=200, seed=3))


def test_shapes_follow_the_robot(data):
    robot = load_robot(data.robot)
    S = robot.dof + 3
    assert len(data) == 64 * 200
    assert data.s.shape == (len(data), S) and data.s_next.shape == (len(data), S)
    assert data.a.shape == (len(data), robot.dof)
    assert data.s.dtype == torch.float32
    assert data.layout == StateLayout(robot.dof)


def test_states_stay_within_limits_and_steps_are_bounded(data):
    robot = load_robot(data.robot)
    L = data.layout
    lo, hi = robot.limits(torch.float32)
    for s in (data.s, data.s_next):
        theta = s[:, L.joints]
        assert bool(((theta >= lo) & (theta <= hi)).all())
    assert float(data.a.abs().max()) <= 0.083 + 1e-6
    # Joints move at the bound most of the time, and the walk covers most of each joint's range.
    assert float((data.a.abs() > 0.08).float().mean()) > 0.2
    span = data.s[:, L.joints].amax(0) - data.s[:, L.joints].amin(0)
    assert bool((span > 0.8 * (hi - lo)).all())


def test_transitions_are_consistent_with_fk(data):
    robot = load_robot(data.robot)
    L = data.layout
    kin = kinematics(robot, "fast")
    for s in (data.s, data.s_next):
        theta, ef = L.split(s)
        assert torch.equal(ef, kin.position(theta))  # the same function on the same numbers
    # a is the realised joint change; s_next's joints are s's plus a (up to float32 rounding).
    assert torch.allclose(data.s[:, L.joints] + data.a, data.s_next[:, L.joints], atol=1e-6, rtol=0)
    # Against float64 FK of the same joints the float32 ef is accurate to float32 precision.
    ref = kin.position(data.s_next[:, L.joints].double())
    assert float((data.s_next[:, L.ef].double() - ref).abs().max()) < 1e-5


def test_walks_are_continuous():
    cfg = BabblingConfig(walkers=5, steps=30, seed=1)
    d = babble(cfg)
    s = d.s.reshape(cfg.steps, cfg.walkers, -1)
    s_next = d.s_next.reshape(cfg.steps, cfg.walkers, -1)
    assert torch.equal(s[1:], s_next[:-1])  # s(t+1) of one transition is s(t) of the next


def test_same_seed_same_bits_other_seed_other_data():
    cfg = BabblingConfig(walkers=50, steps=40, seed=11)
    a, b = babble(cfg), babble(BabblingConfig(**cfg.to_dict()))
    for x, y in zip(a.tensors(), b.tensors(), strict=True):
        assert torch.equal(x, y)
    c = babble(BabblingConfig(walkers=50, steps=40, seed=12))
    assert not torch.equal(a.s, c.s)


def test_retarget_every_step_moves_every_joint_at_the_bound():
    d = babble(BabblingConfig(walkers=100, steps=50, seed=0, retarget_prob=1.0))
    # A fresh uniform target is almost always farther than one step away.
    assert float((d.a.abs() > 0.0829).float().mean()) > 0.95
    d0 = babble(BabblingConfig(walkers=100, steps=50, seed=0))
    assert float((d0.a == 0).float().mean()) > 0.1  # joints that arrived wait for the others


def test_float64_babbling():
    d = babble(BabblingConfig(walkers=10, steps=10, dtype="float64"))
    assert d.s.dtype == d.a.dtype == torch.float64


@pytest.mark.parametrize(
    "kwargs",
    [{"walkers": 0}, {"steps": 0}, {"max_step": 0.0}, {"max_step": float("nan")}, {"retarget_prob": 2.0}],
)
def test_bad_config_is_a_config_error(kwargs):
    with pytest.raises(ConfigError):
        BabblingConfig(**kwargs)


def test_for_transitions_rounds_up():
    cfg = BabblingConfig.for_transitions(1050, walkers=100)
    assert cfg.walkers == 100 and cfg.steps == 11 and cfg.transitions >= 1050
    assert BabblingConfig.for_transitions(5, walkers=100).walkers == 5


def test_round_trip_on_disk(tmp_path):
    d = babble(BabblingConfig(robot="panda", walkers=20, steps=10, seed=5))
    path = save_transitions(d, tmp_path / "b.npz")
    e = load_transitions(path, robot="panda")
    for x, y in zip(d.tensors(), e.tensors(), strict=True):
        assert torch.equal(x, y)
    assert e.robot == "panda" and e.config == d.config
    assert BabblingConfig.from_dict(e.config) == BabblingConfig(robot="panda", walkers=20, steps=10, seed=5)


def test_dataset_for_another_robot_is_refused(tmp_path):
    path = babble(BabblingConfig(walkers=4, steps=4)).save(tmp_path / "b.npz")
    with pytest.raises(DatasetError, match="iiwa14"):
        load_transitions(path, robot="panda")


def test_corrupt_or_foreign_files_are_dataset_errors(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip file")
    with pytest.raises(DatasetError):
        load_transitions(bad)
    with pytest.raises(DatasetError):
        load_transitions(tmp_path / "missing.npz")
    other = save_npz(tmp_path / "o.npz", kind="pairs", robot="iiwa14", config={}, arrays={"x": np.zeros(3)})
    with pytest.raises(DatasetError, match="pairs"):
        load_transitions(other)
    lacking = save_npz(
        tmp_path / "l.npz", kind="babbling", robot="iiwa14", config={}, arrays={"s": np.zeros((2, 10))}
    )
    with pytest.raises(DatasetError, match="lacks"):
        load_transitions(lacking)
    nan = np.full((2, 10), np.nan, dtype=np.float32)
    arrays = {"s": nan, "a": np.zeros((2, 7), np.float32), "s_next": np.zeros((2, 10), np.float32)}
    with pytest.raises(DatasetError, match="NaN"):
        load_transitions(
            save_npz(tmp_path / "n.npz", kind="babbling", robot="iiwa14", config={}, arrays=arrays)
        )


def test_transitions_reject_inconsistent_shapes():
    with pytest.raises(ShapeError):
        Transitions(torch.zeros(4, 9), torch.zeros(4, 7), torch.zeros(4, 10), "iiwa14")
    with pytest.raises(DatasetError):
        Transitions(torch.zeros(4, 10), torch.zeros(3, 7), torch.zeros(4, 10), "iiwa14")


def test_split_is_seeded_and_disjoint():
    d = babble(BabblingConfig(walkers=10, steps=10))
    tr, va = d.split(0.2, seed=4)
    assert len(tr) == 80 and len(va) == 20
    _, va2 = d.split(0.2, seed=4)
    assert torch.equal(va.s, va2.s)
    rows = {tuple(r.tolist()) for r in torch.cat((tr.a, tr.s), 1)} & {
        tuple(r.tolist()) for r in torch.cat((va.a, va.s), 1)
    }
    assert not rows
