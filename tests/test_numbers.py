"""Numbers that are numbers (NumPy scalars, 0-d tensors) taken at the public boundary, and messages that
blame the input at fault: an obstacle's size, a sphere's radius."""

import re
from pathlib import Path

import numpy as np
import pytest
import torch

import kinlearn
from kinlearn import load_robot
from kinlearn.collision import Scene
from kinlearn.collision.geometry import Box, Sphere
from kinlearn.errors import ConfigError, ObstacleError, RobotDescriptionError
from kinlearn.planning.stages import Deadline

ROBOTS = Path(__file__).resolve().parents[1] / "robots"


@pytest.mark.parametrize("seconds", [np.float32(0.05), np.float64(0.05), np.int64(1), torch.tensor(0.05), 1])
def test_a_deadline_is_any_real_number(seconds):
    assert Deadline(seconds).seconds == pytest.approx(float(seconds))


@pytest.mark.parametrize(
    "seconds", [np.float32(-1), torch.tensor([0.05]), torch.tensor(True), "0.05", np.nan]
)
def test_a_deadline_that_is_no_positive_number_is_refused(seconds):
    with pytest.raises(ConfigError, match="deadline"):
        Deadline(seconds)


def test_an_obstacle_of_absurd_size_is_refused_as_an_obstacle_size():
    """A box of 1e300 m: refused where the scene is made, naming its size, not reported later as NaN in a
    candidate path."""
    with pytest.raises(ObstacleError, match=r"boxes hold a position or half extent of 1e\+300 m"):
        Scene.from_primitives([Box((0.5, 0.0, 0.3), (1e300, 0.1, 0.1))])
    with pytest.raises(ObstacleError, match=r"spheres hold .* 2e\+07 m"):
        Scene(spheres=torch.tensor([[2e7, 0.0, 0.0, 0.1]], dtype=torch.float64))
    assert Scene.from_primitives([Sphere((100.0, 0.0, 0.0), 50.0)]).num_spheres == 1


def test_a_sphere_radius_that_is_no_number_is_refused_at_registration(tmp_path):
    panda = load_robot("panda")
    text = (ROBOTS / "panda" / "panda_spherized.urdf").read_text()
    first = re.search(r'<sphere radius="[^"]*"', text).group(0)
    bad = tmp_path / "big.urdf"
    bad.write_text(text.replace(first, '<sphere radius="big"', 1))
    with pytest.raises(RobotDescriptionError, match=r"big\.urdf: a collision sphere of link .* radius 'big'"):
        kinlearn.register_robot("big_panda", panda.urdf_path, ee_frame="panda_hand_tcp", spheres=bad)
    assert "big_panda" not in kinlearn.body.robot.ROBOTS
    from kinlearn.collision.body import urdf_spheres

    with pytest.raises(RobotDescriptionError, match="radius 'big'"):
        urdf_spheres(panda, bad)


def test_configurations_take_numpy_and_torch_numbers_and_keep_python_ones():
    """A NumPy or 0-d torch number in a configuration is taken as the Python number it is, so the
    configuration still writes to config.json."""
    import dataclasses
    import json

    from kinlearn.data.endpoints import EndpointConfig
    from kinlearn.data.problems import ProblemConfig
    from kinlearn.planning.obstacle_baselines import OptimiserConfig
    from kinlearn.training.obstacle_path import ObstacleLossConfig

    configs = [
        EndpointConfig(robot="iiwa14", start_spread=np.float32(0.25)),
        ProblemConfig(time_limit=np.float64(2.0), max_travel=torch.tensor(0.02)),
        OptimiserConfig(lr=np.float32(0.01)),
        ObstacleLossConfig(margin=np.float32(0.05), imitation=np.int64(1)),
    ]
    for cfg in configs:
        values = dataclasses.asdict(cfg)
        json.dumps(values)  # no NumPy or torch scalar left in it
    assert configs[0].start_spread == pytest.approx(0.25) and configs[1].max_travel == pytest.approx(0.02)
    with pytest.raises(ConfigError, match=r"ObstacleLossConfig\.margin must be a finite number ≥ 0"):
        ObstacleLossConfig(margin=np.float32(-1))
    with pytest.raises(ConfigError, match="time_limit"):
        ProblemConfig(time_limit=np.nan)


def test_scene_families_and_the_sampler_take_numpy_numbers():
    from kinlearn.collision.rrt import rrt_connect
    from kinlearn.data.scenes import SCENE_FAMILIES, build_scene

    family = SCENE_FAMILIES[0]
    a = build_scene(family, torch.Generator().manual_seed(0), scale=np.float32(1.0), tool=np.float64(0.0))
    b = build_scene(family, torch.Generator().manual_seed(0), scale=1.0, tool=0.0)
    assert a.primitives == b.primitives
    with pytest.raises(ConfigError, match=r"time_limit must be a number of seconds > 0 \(or inf\)"):
        rrt_connect(None, None, None, None, None, None, time_limit=np.float32(-1.0))
