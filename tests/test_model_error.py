"""The believed (perturbed) robot model and the evaluation that judges planners with the true robot."""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import torch

from kinlearn import kinematics, load_robot
from kinlearn.body.ik import position_ik
from kinlearn.body.perturb import believed_robot, draw_model_error, perturb_urdf, write_perturbed_urdf
from kinlearn.body.robot import ROBOTS
from kinlearn.errors import ConfigError, UnknownRobotError
from kinlearn.evaluation.model_error import (
    PLANNERS,
    evaluate_believed,
    model_error_sweep,
    model_error_table,
    plot_model_error,
    true_goal_error,
)
from kinlearn.evaluation.workspace import heldout_pairs

TRUE = load_robot("iiwa14")


def _origins(urdf: bytes) -> dict[str, np.ndarray]:
    root = ET.fromstring(urdf)
    return {
        el.get("name"): np.array([float(v) for v in el.find("origin").get("xyz").split()])
        for el in root.iter("joint")
    }


def _goals(n: int):
    pairs = heldout_pairs(TRUE, n, range_fraction=0.9)
    return pairs.start[:, : TRUE.dof].double(), pairs.goal[:, TRUE.dof :].double()


def test_perturbed_urdf_loads_and_differs_by_the_requested_amounts(tmp_path):
    path = write_perturbed_urdf(
        "iiwa14", tmp_path / "believed.urdf", length_error=0.03, angle_error_deg=1.5, seed=4
    )
    believed = load_robot(path, ee_frame=ROBOTS["iiwa14"].ee_frame)
    assert believed.joint_names == TRUE.joint_names
    np.testing.assert_array_equal(believed.lower, TRUE.lower)
    np.testing.assert_array_equal(believed.upper, TRUE.upper)
    np.testing.assert_array_equal(believed.velocity_limits, TRUE.velocity_limits)
    true_xyz, new_xyz = _origins(TRUE.urdf), _origins(path.read_bytes())
    ratios = []
    for name, xyz in true_xyz.items():
        length = np.linalg.norm(xyz)
        ratio = np.linalg.norm(new_xyz[name]) / length
        assert 1 - 0.03 <= ratio <= 1 + 0.03
        np.testing.assert_allclose(new_xyz[name] / np.linalg.norm(new_xyz[name]), xyz / length, atol=1e-12)
        ratios.append(ratio)
    assert np.abs(np.array(ratios) - 1).min() > 0.0  # every length is off
    me = draw_model_error("iiwa14", length_error=0.03, angle_error_deg=1.5, seed=4)
    np.testing.assert_allclose(ratios, [me.length_scale[n] for n in true_xyz], rtol=1e-12)
    offsets = me.offsets(TRUE)
    assert offsets.abs().max() <= math.radians(1.5) and offsets.abs().min() > 0
    zero = torch.zeros(7, dtype=torch.float64)
    shift = (kinematics(believed).position(zero) - kinematics(TRUE).position(zero)).norm()
    assert 1e-3 < shift < 0.1
    # An independent parser (Pinocchio) reads the written URDF the same way.
    q = TRUE.sample(20, torch.Generator().manual_seed(0), dtype=torch.float64)
    torch.testing.assert_close(
        kinematics(believed, "pinocchio").position(q), kinematics(believed).position(q), atol=1e-10, rtol=0
    )
    # The in-memory believed robot is the same model.
    same = believed_robot("iiwa14", length_error=0.03, angle_error_deg=1.5, seed=4)
    torch.testing.assert_close(
        kinematics(same).position(q), kinematics(believed).position(q), atol=1e-12, rtol=0
    )


def test_zero_offsets_are_a_shift_of_the_joint_values():
    me = draw_model_error("iiwa14", length_error=0.0, angle_error_deg=2.0, seed=7)
    believed = believed_robot("iiwa14", length_error=0.0, angle_error_deg=2.0, seed=7)
    q = TRUE.sample(200, torch.Generator().manual_seed(1), dtype=torch.float64)
    true_pose = kinematics(TRUE).pose(q + me.offsets(TRUE))
    torch.testing.assert_close(kinematics(believed).pose(q), true_pose, atol=1e-12, rtol=0)
    assert (kinematics(believed).position(q) - kinematics(TRUE).position(q)).norm(dim=-1).max() > 1e-2


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_every_bundled_arm_gets_a_valid_believed_model(name):
    robot = load_robot(name)
    me = draw_model_error(name, length_error=0.0, angle_error_deg=2.0, seed=1)
    believed = believed_robot(name, length_error=0.0, angle_error_deg=2.0, seed=1)
    q = robot.sample(20, torch.Generator().manual_seed(0), dtype=torch.float64)
    torch.testing.assert_close(
        kinematics(believed).pose(q), kinematics(robot).pose(q + me.offsets(robot)), atol=1e-12, rtol=0
    )
    both = believed_robot(name, length_error=0.05, angle_error_deg=2.0, seed=1)
    torch.testing.assert_close(
        kinematics(both, "pinocchio").position(q), kinematics(both).position(q), atol=1e-10, rtol=0
    )


def test_no_error_keeps_the_joints_and_a_seed_fixes_the_draw():
    same = believed_robot("iiwa14", length_error=0.0, angle_error_deg=0.0, seed=3)
    q = TRUE.sample(50, torch.Generator().manual_seed(2), dtype=torch.float64)
    torch.testing.assert_close(kinematics(same).pose(q), kinematics(TRUE).pose(q), atol=0, rtol=0)
    a = perturb_urdf("iiwa14", length_error=0.02, angle_error_deg=1.0, seed=5)
    assert a == perturb_urdf("iiwa14", length_error=0.02, angle_error_deg=1.0, seed=5)
    assert a != perturb_urdf("iiwa14", length_error=0.02, angle_error_deg=1.0, seed=6)
    assert a != perturb_urdf("iiwa14", length_error=0.03, angle_error_deg=1.0, seed=5)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"length_error": -0.01},
        {"length_error": float("nan")},
        {"length_error": 1.0},
        {"angle_error_deg": -1.0},
        {"angle_error_deg": float("inf")},
        {"angle_error_deg": "2"},
        {"seed": -1},
        {"seed": 1.5},
        {"seed": True},
    ],
)
def test_bad_amounts_raise_config_error(kwargs):
    with pytest.raises(ConfigError):
        perturb_urdf("iiwa14", **kwargs)


def test_unknown_robots_raise_unknown_robot_error(tmp_path):
    with pytest.raises(UnknownRobotError, match="iiwa14"):
        perturb_urdf("iiwa15")
    with pytest.raises(UnknownRobotError):
        write_perturbed_urdf(tmp_path / "missing.urdf", tmp_path / "out.urdf")
    with pytest.raises(ConfigError, match="ee_frame"):
        believed_robot(write_perturbed_urdf("iiwa14", tmp_path / "b.urdf"))


def test_evaluation_judges_with_the_true_robot():
    q0, p = _goals(12)
    exact = evaluate_believed(TRUE, TRUE, q0, p, rrt=False)["joint-line"]
    assert exact["error"].max() < 1e-3  # the true model reaches every goal
    wrong = believed_robot("iiwa14", length_error=0.05, angle_error_deg=2.0, seed=0)
    judged = evaluate_believed(TRUE, wrong, q0, p, rrt=False)["joint-line"]
    assert judged["believed_error"].max() < 1e-3  # the planner's own model says it arrived ...
    assert judged["error"][0] > 1e-2 and judged["error"].median() > 1e-2  # ... the true robot did not
    # The judge is the true FK of the last configuration of the executed path.
    q_ik = position_ik(wrong, q0, p)
    torch.testing.assert_close(
        true_goal_error(TRUE, q_ik.unsqueeze(-2), p), judged["error"], atol=1e-12, rtol=0
    )


def test_sweep_table_and_figure(tmp_path):
    results = model_error_sweep(
        levels=((0.0, 0.0), (0.05, 2.0)), n_goals=6, seeds=(0,), rrt=True, calibration_samples=6000
    )
    json.dumps(results)  # JSON-able
    first, last = (lv["planners"] for lv in results["levels"])
    assert set(first) == set(PLANNERS)
    assert first["kinlearn"] == last["kinlearn"] and first["kinlearn"]["same_at_every_level"]
    assert first["joint-line"]["success"] == 1.0
    assert last["joint-line"]["median"] > 1e-2
    assert last["rrt-connect"]["median"] == pytest.approx(last["joint-line"]["median"], abs=1e-9)
    # Calibrated from the true robot's noisy babbling, the wrong URDF is right again.
    assert last["calibrated_ik"]["success"] == 1.0 and last["calibrated_ik"]["median"] < 1e-3
    table = model_error_table(results)
    assert table.count("| 5% / 2° |") == len(PLANNERS) and "†" in table
    png = plot_model_error(results, tmp_path / "model_error.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(ConfigError):
        model_error_sweep(levels=((0.0, float("nan")),), n_goals=4, seeds=(0,))
    with pytest.raises(ConfigError):
        model_error_sweep(n_goals=0)


def test_model_error_command(tmp_path, capsys):
    from kinlearn.cli.main import main

    out = tmp_path / "me"
    args = [
        "model-error",
        "--n-goals",
        "8",
        "--seeds",
        "0",
        "--no-rrt",
        "--no-calibrate",
        "--no-progress",
        "--run-dir",
        str(out),
    ]
    assert main(args) == 0
    assert "kinlearn planner" in capsys.readouterr().out
    assert {"model_error.json", "model_error.md", "config.json"} <= {p.name for p in out.iterdir()}
    assert main(args) == 2  # a finished run is not overwritten silently
