"""Figures are written as valid, non-trivial PNGs; bad arguments fail with typed errors."""

from __future__ import annotations

import struct
import sys

import pytest
import torch

from kinlearn.body.kinematics import kinematics
from kinlearn.body.state import StateLayout
from kinlearn.errors import ConfigError, MissingDependencyError, ShapeError
from kinlearn.evaluation.metrics import PAPER_TABLE2, plan_metrics, trajectory_metrics
from kinlearn.planning.baselines import joint_line

pytest.importorskip("matplotlib")

from kinlearn.evaluation.plots import (
    plot_good_bad,
    plot_histograms,
    plot_trajectories,
    select_examples,
)

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def png_size(path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == PNG_SIGNATURE and data[12:16] == b"IHDR"
    assert len(data) > 20_000  # a drawn figure, not an empty canvas
    return struct.unpack(">II", data[16:24])


@pytest.fixture(scope="module")
def plan(robot):
    g = torch.Generator().manual_seed(0)
    q0 = robot.sample(8, generator=g, margin=0.3)
    qT = robot.sample(8, generator=g, margin=0.3)
    fk = kinematics(robot).position
    layout = StateLayout(robot.dof)
    return joint_line(robot, layout.join(q0, fk(q0)), layout.join(qT, fk(qT)))


def test_plot_trajectories(tmp_path, plan, robot):
    out = plot_trajectories(
        plan, robot, [0, 3, -1], tmp_path / "sub" / "fig3.png", title="joint interpolation"
    )
    assert out == tmp_path / "sub" / "fig3.png"
    w, h = png_size(out)
    assert w > 400 and h > 400
    assert [p.name for p in out.parent.iterdir()] == ["fig3.png"]  # no temporary file left behind
    png_size(plot_trajectories(plan, robot, None, tmp_path / "default.png"))


def test_plot_good_bad(tmp_path, plan, robot):
    w, h = png_size(plot_good_bad(plan, robot, tmp_path / "good_bad.png", k=2, title="two panels"))
    assert w > 1.5 * h  # two panels side by side
    png_size(plot_good_bad(plan, robot, tmp_path / "by_angle.png", k=1, metric="min_angle"))


def test_plot_histograms(tmp_path, plan, robot):
    png_size(plot_histograms(plan_metrics(plan, robot), tmp_path / "fig4.png", paper=PAPER_TABLE2[4]))
    layout = StateLayout(robot.dof)
    m = trajectory_metrics(layout.split(plan.start)[1], plan.waypoints, layout.split(plan.goal)[1])
    png_size(plot_histograms(m, tmp_path / "fig4_plain.png", title="trajectory metrics only", bins=5))


def test_select_examples():
    m = {
        "max_spacing_deviation": torch.tensor([0.3, 0.1, 0.2, 0.0]),
        "min_angle": torch.tensor([90.0, 10, 170, 60]),
    }
    assert select_examples(m, k=2) == ([3, 1], [0, 2])
    assert select_examples(m, k=1, metric="min_angle") == ([2], [1])  # low angles are the bad ones
    assert select_examples(m, k=10) == ([3, 1, 2, 0], [0, 2, 1, 3])
    with pytest.raises(ConfigError):
        select_examples(m, metric="nope")
    with pytest.raises(ConfigError):
        select_examples(m, k=0)


def test_plot_argument_errors(tmp_path, plan, robot):
    with pytest.raises(ConfigError):
        plot_trajectories(plan, robot, [8], tmp_path / "x.png")
    with pytest.raises(ConfigError):
        plot_trajectories(plan, robot, [], tmp_path / "x.png")
    with pytest.raises(ShapeError):
        plot_trajectories(plan[0], robot, [0], tmp_path / "x.png")
    with pytest.raises(ConfigError):
        plot_histograms({"init_distance": torch.zeros(3)}, tmp_path / "x.png")
    assert not (tmp_path / "x.png").exists()


def test_missing_matplotlib_says_how_to_install(tmp_path, plan, robot, monkeypatch):
    for name in [
        m for m in sys.modules if m == "matplotlib" or m.startswith(("matplotlib.", "mpl_toolkits"))
    ]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    monkeypatch.setitem(sys.modules, "mpl_toolkits", None)
    with pytest.raises(MissingDependencyError, match="pip install matplotlib"):
        plot_trajectories(plan, robot, [0], tmp_path / "x.png")
