"""Identification (kinlearn.training.identify) and its commands: a known chain recovered from noisy
babbling of a true robot unlike the bundled ones (written by the test), with and without a prior URDF,
with outliers; a user's registered arm; the CLI end to end (babble → identify → export-urdf, and a
recorded CSV log); the typed errors."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from kinlearn.body.kinematics import kinematics
from kinlearn.body.robot import load_robot, register_robot, unregister_robot
from kinlearn.cli.main import main
from kinlearn.data.babbling import BabblingConfig, babble
from kinlearn.data.recorded import Observations, save_recorded
from kinlearn.errors import ConfigError, DatasetError
from kinlearn.evaluation.model_error import write_perturbed_urdf
from kinlearn.training.identify import IdentifyConfig, identify

#: A quick identification for tests: a small first MLP, fewer iterations.
QUICK = IdentifyConfig(mlp_hidden=(64, 64), mlp_steps=400, references=2, iterations=20)


@pytest.fixture(scope="module")
def true_iiwa(tmp_path_factory):
    """An iiwa14 whose link origins are off by up to 3% and 0.5°, its joint zeros by up to 1.5°."""
    path = tmp_path_factory.mktemp("true") / "true_iiwa.urdf"
    write_perturbed_urdf("iiwa14", path, length_error=0.03, angle_error_deg=1.5, misalign_deg=0.5, seed=7)
    return load_robot(path, "iiwa_link_ee")


def _observe(robot, n, noise, gen, outliers=0.0):
    cfg = BabblingConfig(
        robot=robot.name, walkers=200, steps=n // 200, seed=1, dtype="float64", ef_noise=noise, outliers=outliers,
        urdf=str(robot.urdf_path), ee_frame=robot.ee_frame,
    )  # fmt: skip
    return babble(cfg, robot=robot)


def _fk_error(robot_a, robot_b, gen, n=5000):
    q = robot_a.sample(n, gen, dtype=torch.float64)
    return (kinematics(robot_a, "pinocchio").position(q) - kinematics(robot_b, "fast").position(q)).norm(
        dim=-1
    )


def _exported(result, tmp_path, name="ident"):
    path = tmp_path / f"{name}.urdf"
    path.write_text(result.urdf(name))
    return load_robot(path, result.ee_frame)


def test_known_chain_recovered_with_a_prior(true_iiwa, gen, tmp_path):
    data = _observe(true_iiwa, 8000, 1e-3, gen)
    nominal = load_robot("iiwa14")
    before = _fk_error(nominal, true_iiwa, gen)
    result = identify(data, robot=nominal, config=QUICK)
    err = _fk_error(_exported(result, tmp_path), true_iiwa, gen)
    assert float(before.median()) > 5e-3  # the prior is centimetres off
    assert float(err.median()) < 0.2e-3 and float(err.quantile(0.99)) < 0.6e-3
    r = result.report
    assert r["initialisation"].startswith("prior") and r["outliers_dropped"] < 40
    assert abs(r["noise_sigma"] - 1e-3) < 1e-4  # the noise is seen for what it is
    assert r["undetermined_axis_directions"] == [6]  # the flange point lies on joint 7's axis
    assert result.joint_names == nominal.joint_names


def test_known_chain_recovered_without_any_urdf(true_iiwa, gen, tmp_path):
    data = _observe(true_iiwa, 8000, 1e-3, gen)
    result = identify(data, dof=7, config=QUICK)
    assert result.report["initialisation"].startswith("no prior")
    assert result.model.robot_name == "chain" and result.ee_frame == "ee" and result.base_link == "base"
    err = _fk_error(_exported(result, tmp_path), true_iiwa, gen)
    assert float(err.median()) < 0.2e-3 and float(err.quantile(0.99)) < 0.6e-3


def test_outliers_are_dropped(true_iiwa, gen, tmp_path):
    data = _observe(true_iiwa, 8000, 1e-3, gen, outliers=0.02)
    result = identify(data, robot=load_robot("iiwa14"), config=QUICK)
    dropped = result.report["outliers_dropped"]
    assert 0.015 * 7200 < dropped < 0.03 * 7200  # 2% of the fitted samples, give or take
    err = _fk_error(_exported(result, tmp_path), true_iiwa, gen)
    assert float(err.median()) < 0.25e-3


def test_a_registered_arm_is_identified(true_iiwa, gen):
    register_robot("calib_arm", true_iiwa.urdf_path, "iiwa_link_ee")
    try:
        data = _observe(load_robot("calib_arm"), 6000, 5e-4, gen)
        result = identify(data, robot="calib_arm", prior=False, config=QUICK)
        assert result.model.robot_name == "calib_arm"
        assert result.joint_names == true_iiwa.joint_names
        q = true_iiwa.sample(500, gen, dtype=torch.float64)
        with torch.no_grad():
            err = (result.model.position(q) - kinematics(true_iiwa).position(q)).norm(dim=-1)
        assert float(err.median()) < 0.2e-3
    finally:
        unregister_robot("calib_arm")


def test_identify_refuses_bad_input(gen):
    theta = torch.zeros(100, 7, dtype=torch.float64)
    with pytest.raises(DatasetError, match="at least"):
        identify((theta, torch.zeros(100, 3, dtype=torch.float64)), dof=7)
    with pytest.raises(DatasetError, match="theta"):
        identify((theta, torch.zeros(100, 2, dtype=torch.float64)), dof=7)
    with pytest.raises(DatasetError, match="joints"):
        identify((torch.zeros(5000, 6, dtype=torch.float64), torch.zeros(5000, 3)), robot="iiwa14")
    with pytest.raises(ConfigError):
        identify("x.csv", robot="iiwa14", prior="not a robot")
    with pytest.raises(ConfigError):
        identify(42, dof=7)
    bad = theta.clone()
    bad[3, 2] = float("nan")
    with pytest.raises(Exception, match=r"NaN|finite"):
        identify((bad, torch.zeros(100, 3)), dof=7)
    with pytest.raises(ConfigError):
        IdentifyConfig(holdout=0.7)
    with pytest.raises(ConfigError):
        IdentifyConfig(iterations=0)


def test_cli_babble_identify_export(true_iiwa, tmp_path, gen, capsys):
    """The calibration a user runs: noisy observations of an arm, the chain, a URDF others load."""
    urdf = str(true_iiwa.urdf_path)
    babble_dir = tmp_path / "babble"
    args = ["babble", "--urdf", urdf, "--ee-frame", "iiwa_link_ee", "--ef-noise", "0.001"]
    assert main([*args, "--transitions", "8000", "--walkers", "200", "--run-dir", str(babble_dir)]) == 0
    data = babble_dir / "babbling.npz"
    quick = ["--holdout", "0.1", "--quiet"]
    # A recorded CSV log of the same observations, through the same command.
    obs = Observations.from_transitions(load_babbling(data), joint_names=true_iiwa.joint_names)
    csv = save_recorded(tmp_path / "log.csv", obs)
    assert (
        main(["identify", "--data", str(csv), "--robot", "iiwa14", *quick, "--run-dir", str(tmp_path / "id")])
        == 0
    )
    assert (tmp_path / "id" / "chain.pt").is_file() and (tmp_path / "id" / "report.json").is_file()
    out = tmp_path / "calibrated.urdf"
    assert main(["export-urdf", str(tmp_path / "id"), "--out", str(out)]) == 0
    assert "Pinocchio FK against the chain" in capsys.readouterr().out
    exported = load_robot(out, "iiwa_link_ee")  # named as the robot names its frames and joints
    assert exported.joint_names == true_iiwa.joint_names and exported.root_link == "iiwa_link_0"
    np.testing.assert_allclose(exported.velocity_limits, true_iiwa.velocity_limits)
    err = _fk_error(exported, true_iiwa, gen)
    assert float(err.median()) < 0.2e-3
    # Refusals: exit 2, nothing written.
    assert (
        main(
            [
                "identify",
                "--data",
                str(data),
                "--robot",
                "iiwa14",
                "--dof",
                "7",
                "--run-dir",
                str(tmp_path / "x"),
            ]
        )
        == 2
    )
    assert (
        main(
            ["identify", "--data", str(tmp_path / "none.npz"), "--dof", "7", "--run-dir", str(tmp_path / "y")]
        )
        == 2
    )
    assert main(["identify", "--data", str(data), "--urdf", urdf, "--run-dir", str(tmp_path / "z")]) == 2
    assert not any((tmp_path / d).exists() for d in ("x", "y", "z"))
    assert main(["export-urdf", str(tmp_path / "id"), "--out", str(tmp_path / "a.txt")]) == 2
    assert main(["export-urdf", str(tmp_path / "nothing"), "--out", str(tmp_path / "a.urdf")]) == 2


def load_babbling(path):
    from kinlearn.data.babbling import load_transitions

    return load_transitions(path)


def test_a_user_urdf_prior_for_a_named_arm(true_iiwa, gen, tmp_path):
    """A rough URDF of the arm as the prior (not the arm's own): the chain is the arm's by name."""
    rough = load_robot(
        write_perturbed_urdf("iiwa14", tmp_path / "rough.urdf", length_error=0.02, seed=3), "iiwa_link_ee"
    )
    data = _observe(true_iiwa, 6000, 1e-3, gen)
    result = identify(data, robot="iiwa14", prior=rough, config=QUICK)
    assert result.model.robot_name == "iiwa14" and result.model.config.robot == "iiwa14"
    err = _fk_error(_exported(result, tmp_path), true_iiwa, gen)
    assert float(err.median()) < 0.25e-3


def test_work_is_bounded_by_max_samples(true_iiwa, gen):
    data = _observe(true_iiwa, 4000, 1e-3, gen)
    cfg = IdentifyConfig(max_samples=1500, iterations=5)
    result = identify(data, robot="iiwa14", config=cfg)
    assert result.report["subsampled_from"] > 4000 and result.report["samples"] == 1500
    with pytest.raises(ConfigError):
        IdentifyConfig(max_samples=0)


def test_an_identification_saved_loads_with_its_names(true_iiwa, gen, tmp_path):
    from kinlearn.errors import CheckpointError
    from kinlearn.models.forward_inverse import AnalyticFM, save_model
    from kinlearn.training.identify import Identification

    result = identify(_observe(true_iiwa, 4000, 1e-3, gen), robot="iiwa14", config=QUICK)
    back = Identification.load(result.save(tmp_path / "chain.pt"))
    assert (back.joint_names, back.base_link, back.ee_frame, back.velocity) == (
        result.joint_names, result.base_link, result.ee_frame, result.velocity,
    )  # fmt: skip
    assert back.urdf() == result.urdf() and back.report["samples"] == result.report["samples"]
    with pytest.raises(CheckpointError, match="not an identified chain"):
        Identification.load(save_model(AnalyticFM("iiwa14"), tmp_path / "analytic.pt"))
