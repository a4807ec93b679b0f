import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import pytest
import torch

torch.set_num_threads(min(2, os.cpu_count() or 1))

ALL_ROBOTS = ("iiwa14", "panda", "ur5", "xarm7", "z1")


@pytest.fixture
def gen() -> torch.Generator:
    return torch.Generator().manual_seed(1234)
