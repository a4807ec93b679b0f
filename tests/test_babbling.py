"""Motor babbling: limits, step bound, FK consistency, determinism, datasets on disk, sensor noise and
outliers, any URDF as the true robot."""

import numpy as np
import pytest
import torch

from kinlearn import ConfigError, Robot, ShapeError, kinematics, load_robot
from kinlearn.body.state import StateLayout
from kinlearn.data.babbling import BabblingConfig, Transitions, babble, load_transitions, save_transitions
from kinlearn.errors import DatasetError
from kinlearn.io import file_sha256, save_npz


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


# --------------------------------------------------------------------------------------------------
# Sensor noise, outliers, and any URDF as the true robot
# --------------------------------------------------------------------------------------------------


def _fk_residual(d: Transitions, robot) -> torch.Tensor:
    """ef − FK(θ) of every state ``(N, 3)`` (float64)."""
    L = d.layout
    theta, ef = L.split(d.s)
    return ef.double() - kinematics(robot, "fast").position(theta.double())


def test_noise_is_per_observed_state_and_leaves_the_joints_alone():
    base = {"walkers": 200, "steps": 50, "seed": 4, "dtype": "float64"}
    clean = babble(BabblingConfig(**base))
    noisy = babble(BabblingConfig(**base, ef_noise=0.001))
    L = clean.layout
    # The walk and the actions are the noiseless ones, bit for bit (the noise is drawn after the walk).
    assert torch.equal(noisy.a, clean.a)
    assert torch.equal(noisy.s[:, L.joints], clean.s[:, L.joints])
    assert torch.equal(noisy.s_next[:, L.joints], clean.s_next[:, L.joints])
    # Gaussian noise of 1 mm per coordinate on each state's ef.
    r = _fk_residual(noisy, load_robot("iiwa14"))
    assert abs(float(r.std()) - 0.001) < 3e-5 and float(r.mean().abs()) < 3e-5
    assert float(r.abs().max()) < 0.006
    # A state is observed once: s' of one transition is s of the same walker's next one.
    s = noisy.s.reshape(50, 200, -1)
    s_next = noisy.s_next.reshape(50, 200, -1)
    assert torch.equal(s[1:], s_next[:-1])
    # Deterministic, and other noise from another seed.
    again = babble(BabblingConfig(**base, ef_noise=0.001))
    assert torch.equal(again.s, noisy.s)


def test_outliers_are_the_share_asked_for_at_the_size_asked_for():
    cfg = BabblingConfig(walkers=100, steps=99, seed=1, dtype="float64", outliers=0.02, outlier_size=0.05)
    d = babble(cfg)
    robot = load_robot("iiwa14")
    L = d.layout
    states = torch.cat((d.s.reshape(99, 100, -1), d.s_next.reshape(99, 100, -1)[-1:]))  # every state once
    theta, ef = L.split(states.reshape(-1, L.size))
    dist = (ef - kinematics(robot, "fast").position(theta)).norm(dim=-1)
    moved = dist > 1e-9
    assert int(moved.sum()) == round(0.02 * 100 * 100)
    assert torch.allclose(dist[moved], torch.full_like(dist[moved], 0.05), atol=1e-12)
    # With noise as well: outliers stand out by their size.
    noisy = babble(BabblingConfig(**{**cfg.to_dict(), "ef_noise": 0.001}))
    r = _fk_residual(noisy, robot).norm(dim=-1)
    assert 0.015 < float((r > 0.02).double().mean()) < 0.025


def test_noiseless_records_are_unchanged_and_old_configs_load(tmp_path):
    cfg = BabblingConfig(walkers=4, steps=4)
    assert set(cfg.to_dict()) == {"robot", "walkers", "steps", "max_step", "seed", "retarget_prob", "dtype"}
    noisy = BabblingConfig(walkers=4, steps=4, ef_noise=0.002, outliers=0.1)
    assert BabblingConfig.from_dict(noisy.to_dict()) == noisy
    assert noisy.to_dict()["ef_noise"] == 0.002 and noisy.to_dict()["outlier_size"] == 0.05
    assert noisy.to_dict()["urdf"] is None  # once one is set, every field is recorded
    # A file written before the sensor fields existed.
    old = {"robot": "iiwa14", "walkers": 4, "steps": 4, "max_step": 0.083, "seed": 0, "retarget_prob": 0.0}
    d = babble(cfg)
    arrays = {k: t.numpy() for k, t in zip(("s", "a", "s_next"), d.tensors(), strict=True)}
    path = save_npz(tmp_path / "old.npz", kind="babbling", robot="iiwa14", config=old, arrays=arrays)
    loaded = load_transitions(path, robot="iiwa14")
    assert BabblingConfig.from_dict(loaded.config) == cfg
    assert BabblingConfig.from_dict(loaded.config).ef_noise == 0.0


@pytest.mark.parametrize(
    "kwargs",
    [
        {"ef_noise": -0.001},
        {"ef_noise": float("nan")},
        {"ef_noise": float("inf")},
        {"outliers": 1.0},
        {"outliers": -0.1},
        {"outlier_size": 0.0},
        {"outlier_size": float("nan")},
        {"ee_frame": "tool0"},
    ],
)
def test_bad_sensor_settings_are_config_errors(kwargs):
    with pytest.raises(ConfigError):
        BabblingConfig(**kwargs)


def test_any_urdf_is_the_true_robot(tmp_path):
    from kinlearn.evaluation.model_error import write_perturbed_urdf

    path = write_perturbed_urdf(
        "iiwa14", tmp_path / "bent.urdf", length_error=0.03, angle_error_deg=1.0, seed=5
    )
    with pytest.raises(ConfigError, match="ee_frame"):
        BabblingConfig(urdf=str(path))
    with pytest.raises(ConfigError, match="no URDF file"):
        BabblingConfig(urdf=str(tmp_path / "none.urdf"), ee_frame="iiwa_link_ee")
    cfg = BabblingConfig(walkers=20, steps=10, urdf=str(path), ee_frame="iiwa_link_ee", dtype="float64")
    assert cfg.robot == "bent" and cfg.urdf_sha256 == file_sha256(path)
    d = babble(cfg)
    assert d.robot == "bent" and d.config["urdf_sha256"] == cfg.urdf_sha256
    true = load_robot(path, ee_frame="iiwa_link_ee")
    assert float(_fk_residual(d, true).abs().max()) < 1e-12
    assert float(_fk_residual(d, load_robot("iiwa14")).abs().max()) > 1e-3  # not the bundled arm
    # Named as the user likes; the recorded hash guards the file.
    assert babble(BabblingConfig(**{**cfg.to_dict(), "robot": "mine"})).robot == "mine"
    path.write_bytes(path.read_bytes() + b"\n")
    with pytest.raises(ConfigError, match="the URDF changed"):
        babble(cfg)
    with pytest.raises(ConfigError, match="not the babbling config's URDF"):
        babble(cfg, robot=Robot("bent", load_robot("iiwa14").urdf, "iiwa_link_ee"))


def test_babble_command_with_noise_and_a_urdf(tmp_path, capsys):
    from kinlearn.cli.main import main
    from kinlearn.evaluation.model_error import write_perturbed_urdf

    urdf = write_perturbed_urdf("iiwa14", tmp_path / "bent.urdf", seed=1)
    run = tmp_path / "b"
    argv = ["babble", "--transitions", "400", "--walkers", "20", "--ef-noise", "0.001", "--outliers", "0.05"]
    assert main([*argv, "--urdf", str(urdf), "--ee-frame", "iiwa_link_ee", "--run-dir", str(run)]) == 0
    true = load_robot(urdf, ee_frame="iiwa_link_ee")
    d = load_transitions(run / "babbling.npz", robot=Robot("bent", true.urdf, true.ee_frame))
    cfg = BabblingConfig.from_dict(d.config)
    assert (cfg.ef_noise, cfg.outliers, cfg.outlier_size) == (0.001, 0.05, 0.05)
    assert cfg.urdf == str(urdf) and cfg.urdf_sha256 == file_sha256(urdf)
    assert "bent" in capsys.readouterr().out
    assert main([*argv, "--urdf", str(urdf), "--run-dir", str(tmp_path / "no")]) == 2
    assert "--ee-frame" in capsys.readouterr().err and not (tmp_path / "no").exists()
    with pytest.raises(SystemExit):  # refused by the option's type: a usage message, status 2
        main([*argv[:-1], "1.5", "--run-dir", str(tmp_path / "no")])
    assert main([*argv, "--robot", "panda", "--run-dir", str(tmp_path / "p")]) == 0
    assert load_transitions(tmp_path / "p" / "babbling.npz").robot == "panda"
