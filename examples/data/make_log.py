"""Make ``iiwa14_log.csv``, the recorded log the calibration examples read.

    python examples/data/make_log.py

It is not a real robot's log: it is motor babbling of kinlearn's iiwa14 (its bundled URDF) by
:func:`kinlearn.data.babbling.babble`, 10 walkers × 150 steps (seed 3), every observed end-effector
position given Gaussian sensor noise of 1 mm per axis, as a camera or motion capture would see it. Joint
values (rad) and positions (m, base frame) are written to 1e-6; each walker is one episode. The CSV
layout is :mod:`kinlearn.data.recorded`'s: a column per joint named as the robot's joints, ``ef_x, ef_y,
ef_z``, ``episode``. ``tests/test_docs.py`` checks that the shipped file is what it says it is.
"""

from __future__ import annotations

from pathlib import Path

import torch

import kinlearn
from kinlearn.data.babbling import BabblingConfig, babble
from kinlearn.data.recorded import Observations

#: The babbling that makes the log; its noise is the log's stated sensor noise.
CONFIG = BabblingConfig(robot="iiwa14", walkers=10, steps=150, ef_noise=0.001, seed=3, dtype="float64")
LOG = Path(__file__).with_name("iiwa14_log.csv")


def make(path: Path = LOG) -> Path:
    robot = kinlearn.load_robot("iiwa14")
    obs = Observations.from_transitions(babble(CONFIG, robot=robot), robot.joint_names)
    values = torch.cat((obs.theta, obs.ef), 1).numpy()
    lines = [",".join([*robot.joint_names, "ef_x", "ef_y", "ef_z", "episode"])]
    lines += [
        ",".join(f"{v:.6f}" for v in row) + f",{int(e)}" for row, e in zip(values, obs.episode, strict=True)
    ]
    path.write_text("\n".join(lines) + "\n")
    return path


if __name__ == "__main__":
    print(f"wrote {make()}")
