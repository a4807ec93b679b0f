"""The supervised (imitation) trajectory-model baseline."""

import pytest
import torch

from kinlearn import ConfigError, load_robot
from kinlearn.data.endpoints import EndpointConfig, make_endpoints
from kinlearn.models.forward_inverse import AnalyticFM, AnalyticIM
from kinlearn.models.trajectory import TMConfig, TrajectoryModel
from kinlearn.planning.baselines import joint_line
from kinlearn.planning.planner import Planner
from kinlearn.training.imitation import imitation_loss, imitation_targets, train_imitation
from kinlearn.training.loop import OptimConfig

FAST = OptimConfig(name="adam", lr=1e-2)


@pytest.fixture(scope="module")
def pairs():
    return make_endpoints(EndpointConfig(n=128, seed=5))


@pytest.fixture(scope="module")
def trained(pairs):
    history: list[float] = []
    tm = train_imitation(pairs, epochs=20, batch_size=16, optim=FAST, seed=0, progress=False, history=history)
    return tm, history


def test_targets_are_fk_of_joint_interpolation(pairs):
    robot = load_robot("iiwa14")
    targets = imitation_targets(pairs)
    assert targets.shape == (len(pairs), 10, 3)
    expected = joint_line(robot, pairs.start, pairs.goal, steps=11).waypoints
    assert torch.equal(targets, expected)


def test_training_loss_falls(trained):
    _, history = trained
    assert len(history) == 20
    assert history[-1] < 0.3 * history[0]


def test_waypoints_approach_the_targets(pairs, trained):
    tm, _ = trained
    torch.manual_seed(0)
    untrained = TrajectoryModel(TMConfig())
    untrained.fit_normalization(pairs.start, pairs.goal)
    targets = imitation_targets(pairs)
    before = imitation_loss(untrained, pairs, targets)
    after = imitation_loss(tm, pairs, targets)
    assert after < 0.3 * before
    with torch.no_grad():
        err_after = (tm(pairs.start, pairs.goal) - targets).norm(dim=-1).mean()
        err_before = (untrained(pairs.start, pairs.goal) - targets).norm(dim=-1).mean()
    assert err_after < 0.6 * err_before


def test_deterministic_for_a_seed(pairs, trained):
    tm, _ = trained
    again = train_imitation(pairs, epochs=20, batch_size=16, optim=FAST, seed=0, progress=False)
    for a, b in zip(tm.state_dict().values(), again.state_dict().values(), strict=True):
        assert torch.equal(a, b)


def test_planner_plans_with_the_imitation_tm(pairs, trained):
    tm, _ = trained
    robot = load_robot("iiwa14")
    planner = Planner(robot, tm, AnalyticFM(robot), AnalyticIM(robot))
    plan = planner.plan(pairs.start[:5], pairs.goal[:5])
    assert plan.waypoints.shape == (5, 10, 3) and plan.joints.shape == (5, 12, 7)
    # Through the exact FM/IM the rollout follows the imitated TM's waypoints.
    tracking = (plan.ef[:, 1:-1] - plan.waypoints).norm(dim=-1)
    assert float(tracking.median()) < 1e-3  # the executed path goes through the TM's waypoints
    assert torch.equal(plan.joints[:, 0], pairs.start[:5, :7])


def test_bad_arguments(pairs):
    with pytest.raises(ConfigError):
        train_imitation(pairs, epochs=0, progress=False)
    with pytest.raises(ConfigError, match="panda"):
        train_imitation(pairs, epochs=1, progress=False, tm_config=TMConfig(robot="panda", dof=7))
