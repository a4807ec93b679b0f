"""The planner shipped for every bundled arm: held-out pairs, limits, timing, the robot it belongs to;
and ``kinlearn view --gif``."""

import argparse
import shutil

import numpy as np
import pytest
import torch
from conftest import ALL_ROBOTS

import kinlearn
from kinlearn.baselines import JointLine
from kinlearn.body.robot import ROBOTS, load_robot
from kinlearn.cli.view import register
from kinlearn.errors import CheckpointError, ConfigError
from kinlearn.evaluation.metrics import plan_metrics
from kinlearn.evaluation.workspace import evaluate_workspace, heldout_pairs
from kinlearn.io import load_checkpoint
from kinlearn.models.chain import ChainFM
from kinlearn.models.forward_inverse import load_fm, load_im
from kinlearn.planning.planner import DEFAULT_CHECKPOINTS, Planner

#: Held-out workspace pairs per arm (uniform within ±90% of the joint range, a seed no training used).
N_PAIRS = 8


@pytest.fixture(scope="module", params=ALL_ROBOTS)
def shipped(request):
    planner = Planner.default(request.param)
    return planner, heldout_pairs(planner.robot, n=N_PAIRS)


def test_every_bundled_arm_has_a_shipped_planner():
    shipped = sorted(p.name for p in DEFAULT_CHECKPOINTS.iterdir() if (p / "tm.pt").is_file())
    assert shipped == sorted(ROBOTS) == sorted(ALL_ROBOTS)


#: Largest shipped joint-space planner (tm.pt + fm.pt + im.pt) per arm, in KB: weights are float16.
MAX_SHIPPED_KB = {"iiwa14": 480, "panda": 270, "ur5": 270, "xarm7": 270, "z1": 270}


@pytest.mark.parametrize("robot", ALL_ROBOTS)
def test_shipped_planners_are_small_and_store_float16_weights(robot):
    folder = DEFAULT_CHECKPOINTS / robot
    assert (
        sum((folder / f).stat().st_size for f in ("tm.pt", "fm.pt", "im.pt")) <= MAX_SHIPPED_KB[robot] * 1024
    )
    for f in ("tm.pt", "fm.pt", "im.pt"):
        state = load_checkpoint(folder / f, kind=None, robot=robot)["state_dict"]
        for k, v in state.items():
            if v.is_floating_point():  # layers in float16; normalisation and limits exact
                assert v.dtype == (torch.float16 if k.rsplit(".", 1)[-1] in ("weight", "bias") else v.dtype)
        assert any(v.dtype == torch.float16 for v in state.values())


def test_checkpoints_carry_their_arm(shipped):
    planner, _ = shipped
    name = planner.robot.name
    folder = DEFAULT_CHECKPOINTS / name
    assert planner.robot is load_robot(name)
    assert planner.tm.robot_name == planner.fm.robot_name == planner.im.robot_name == name
    assert planner.tm.config.dof == planner.robot.dof
    for kind in ("tm", "fm", "im"):
        assert load_checkpoint(folder / f"{kind}.pt", kind=None, robot=name)["robot"] == name
    for other in ALL_ROBOTS:
        if other == name:
            continue
        with pytest.raises(CheckpointError, match=f"trained for robot '{name}', not '{other}'"):
            Planner.load(folder, robot=other)
        with pytest.raises(CheckpointError, match=f"trained for robot '{name}'"):
            load_fm(folder / "fm.pt", robot=other)
        with pytest.raises(CheckpointError, match=f"trained for robot '{name}'"):
            load_im(folder / "im.pt", robot=other)


def test_shipped_planner_reaches_held_out_goal_states(shipped):
    planner, pairs = shipped
    robot, dof = planner.robot, planner.robot.dof
    plan = kinlearn.plan(pairs.start, pairs.goal, robot=robot.name)
    assert plan.robot == robot.name and plan.joints.shape == (N_PAIRS, 12, dof)
    assert torch.equal(plan.joints, planner.plan(pairs.start, pairs.goal).joints)
    assert bool(plan.success.all())
    m = plan_metrics(plan, robot)
    assert float(m["state_success"].min()) == 1.0
    assert float(m["limit_violation"].max()) == 0.0
    lo, hi = robot.limits(torch.float64)
    assert bool(((plan.joints >= lo) & (plan.joints <= hi)).all())
    # the path starts at the start's joints and ends exactly at the goal's
    assert torch.equal(plan.joints[:, 0], pairs.start[:, :dof].to(plan.joints.dtype))
    assert torch.equal(plan.joints[:, -1], pairs.goal[:, :dof].to(plan.joints.dtype))
    assert float((plan.ef[:, -1] - pairs.goal[:, dof:].double()).norm(dim=-1).max()) < 1e-5
    # a planner, not joint interpolation left untouched: its intermediate joints differ from the line
    f = torch.arange(12, dtype=torch.float64)[:, None] / 11
    line = plan.joints[:, :1] + f * (plan.joints[:, -1:] - plan.joints[:, :1])
    assert float((plan.joints - line).abs().amax()) > 1e-3


def test_shipped_planner_shortens_the_hand_path_without_sharper_turns(shipped):
    """On 64 held-out pairs: the executed end-effector path is shorter than joint interpolation's (median
    ratio measured 0.72-0.91 across the arms) and turns sharper than 90° are no more common."""
    planner, _ = shipped
    robot = planner.robot
    pairs = heldout_pairs(robot, n=64)
    res = evaluate_workspace(
        robot,
        pairs,
        {
            "planner": planner,
            "joint interpolation": JointLine(robot),
        },
    )
    assert res["planner"]["state_success"] == 1.0
    assert res["planner"]["path_ratio_median"] <= 0.95
    assert res["planner"]["sharp_turn"] <= res["joint interpolation"]["sharp_turn"] + 0.05


def test_shipped_plan_is_timed_within_velocity_and_acceleration_limits(shipped):
    planner, pairs = shipped
    robot, dof = planner.robot, planner.robot.dof
    acc = np.linspace(2.0, 4.0, dof)  # rad/s², given per joint
    plan = planner.plan(pairs.start[0, :dof], pairs.goal[0, :dof])
    traj = plan.timed(acceleration_limits=acc)
    vel = robot.velocity_limits
    assert traj.robot == robot.name and np.array_equal(traj.acceleration_limits, acc)
    assert np.array_equal(traj.velocity_limits, vel)
    assert (np.abs(traj.qd) <= vel * (1 + 1e-6)).all()
    assert (np.abs(traj.qdd) <= acc * (1 + 1e-6)).all()
    assert (traj.q >= robot.lower - 1e-9).all() and (traj.q <= robot.upper + 1e-9).all()
    np.testing.assert_allclose(traj.q[0], plan.joints[0].numpy(), atol=1e-9)
    np.testing.assert_allclose(traj.q[-1], plan.joints[-1].numpy(), atol=1e-9)
    assert np.abs(traj.qd[[0, -1]]).max() < 1e-6  # rest to rest
    # no joint can cover its distance faster than at full speed all the way
    moves = np.abs(plan.joints[-1] - plan.joints[0]).numpy()
    assert traj.duration >= (moves / vel).max() > 0


def test_an_arm_without_a_shipped_planner_is_refused(tmp_path):
    spec = ROBOTS["iiwa14"]
    urdf = shutil.copy(load_robot("iiwa14").urdf_path, tmp_path / "myarm.urdf")
    robot = load_robot(urdf, ee_frame=spec.ee_frame)
    with pytest.raises(
        ConfigError, match=r"ships no planner for 'myarm' \(shipped: iiwa14, panda, ur5, xarm7, z1\)"
    ):
        kinlearn.plan(torch.zeros(robot.dof), torch.zeros(robot.dof), robot=robot)


# ---------------------------------------------------------------------------------------------- view


def _view_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="kinlearn")
    register(parser.add_subparsers())
    return parser


def test_view_writes_a_gif_of_the_plan(tmp_path, capsys):
    pil = pytest.importorskip("PIL.Image")
    pytest.importorskip("matplotlib")
    start, goal = "-0.5,1.0,-1.2,0.3,0.2,-0.4", "0.8,0.6,-0.5,-0.6,-0.3,1.0"
    out = tmp_path / "z1.gif"
    args = _view_parser().parse_args(
        ["view", "--robot", "z1", "--start", start, "--goal", goal, "--gif", str(out), "--fps", "20"]
    )
    assert args.run(args) == 0
    text = capsys.readouterr().out
    assert "1/1 plans succeeded" in text and str(out) in text
    plan = kinlearn.plan(
        [float(v) for v in start.split(",")], [float(v) for v in goal.split(",")], robot="z1"
    )
    with pil.open(out) as im:
        assert im.format == "GIF" and im.n_frames == plan.joints.shape[0] == 12
        assert im.info["duration"] == 50  # ms per frame at 20 fps


def test_view_refuses_bad_input(tmp_path):
    parser = _view_parser()
    args = parser.parse_args(["view", "--robot", "z1", "--start", "0,0,0,0,0,0", "--goal", "0,0,0,0,0,0"])
    args.gif = tmp_path / "plan.png"
    with pytest.raises(ConfigError, match=r"--gif must name a \.gif file"):
        args.run(args)
    assert not args.gif.exists()
    with pytest.raises(SystemExit):
        parser.parse_args(["view", "--robot", "z1", "--start", "0,0,0,0,0,0", "--goal", "0,0", "--port", "0"])


def test_shipped_chain_reaches_held_out_positions(shipped):
    """Position goals through the arm's identified chain (learned from 1 mm-noisy babbling, no URDF):
    within 1 cm on held-out pairs, the analytic FK judging; the chain is the arm's and nobody else's."""
    planner, _ = shipped
    robot = planner.robot
    assert isinstance(planner.chain, ChainFM) and planner.chain.robot_name == robot.name
    payload = load_checkpoint(DEFAULT_CHECKPOINTS / robot.name / "chain.pt", kind="fm", robot=robot.name)
    assert payload["extra"]["report"]["initialisation"].startswith("no prior")
    pairs = heldout_pairs(robot, n=200)
    plan = kinlearn.plan(
        pairs.start[:, : robot.dof], goal_position=pairs.goal[:, robot.dof :], robot=robot.name
    )
    err = plan.goal_error.double()
    assert float((err <= 0.01).double().mean()) >= 0.99 and float(err.median()) <= 1e-3
    assert bool(robot.within_limits(plan.joints.double()).all())  # float32 joints: 1e-6 rad of rounding
    other = next(n for n in ALL_ROBOTS if n != robot.name and load_robot(n).dof == robot.dof)
    with pytest.raises(CheckpointError):
        load_fm(DEFAULT_CHECKPOINTS / robot.name / "chain.pt", robot=other)


def test_position_goals_are_batch_independent_and_bounded():
    """Position goals through the shipped chain: a problem planned alone and in a batch of 64 gives the
    same plan (1e-6 rad), a goal the start already reaches is a move of zero, and a goal far outside
    the arm's reach is refused before any work (it used to hang)."""
    robot = load_robot("iiwa14")
    pairs = heldout_pairs(robot, n=64)
    start, goal = pairs.start[:, :7].double(), pairs.goal[:, 7:].double()
    batch = kinlearn.plan(start, goal_position=goal)
    for k in (0, 17, 63):
        alone = kinlearn.plan(start[k], goal_position=goal[k])
        assert torch.allclose(alone.joints, batch.joints[k], atol=1e-6, rtol=0)
        assert bool(alone.success) == bool(batch.success[k])
    here = Planner.default("iiwa14").chain.position(start[5])
    still = kinlearn.plan(start[5], goal_position=here.detach())
    assert torch.equal(still.joints, start[5].expand(still.joints.shape[0], 7))
    with pytest.raises(kinlearn.DomainError, match="reaches about"):
        kinlearn.plan(start[0], goal_position=[1000.0, 0.0, 0.0])
    with pytest.raises(kinlearn.DomainError):
        kinlearn.plan(start[0], goal_position=[1e300, 0.0, 0.0])
