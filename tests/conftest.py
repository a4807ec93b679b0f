import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import pytest
import torch

torch.set_num_threads(min(2, os.cpu_count() or 1))

ALL_ROBOTS = ("iiwa14", "panda", "ur5", "xarm7", "z1")


def state_pairs(robot, n: int, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """``n`` start and ``n`` goal states [θ, ef] (float32) of joints drawn within ``robot``'s limits."""
    from kinlearn.body.kinematics import kinematics

    g = torch.Generator().manual_seed(seed)
    q = robot.sample(2 * n, g, dtype=torch.float64)
    s = torch.cat((q, kinematics(robot).position(q)), -1).float()
    return s[:n], s[n:]


@pytest.fixture
def gen() -> torch.Generator:
    return torch.Generator().manual_seed(1234)


# Shared objects that no test changes: one for the whole suite (load_robot caches the robot anyway).
# A test that needs its own copy, another arm or a parametrised one defines a fixture of that name.


@pytest.fixture(scope="session")
def robot():
    """The iiwa14, the arm most tests plan with."""
    from kinlearn.body.robot import load_robot

    return load_robot("iiwa14")


@pytest.fixture(scope="session")
def body(robot):
    """The iiwa14's collision spheres (Drake's 12 and the base cover), float64."""
    from kinlearn.collision.body import body_spheres

    return body_spheres(robot).double()
