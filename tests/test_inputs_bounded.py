"""Inputs held to one standard: numbers that are numbers, bounded work, typed errors for files and odd
batches, and answers that do not depend on what else is in the batch."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import torch

import kinlearn
from kinlearn.checks import as_int, as_real
from kinlearn.errors import ConfigError
from kinlearn.planning.timing import MAX_SAMPLES, time_parameterize

START = torch.tensor([-1.2, 0.9, 0.5, -1.6, 0.3, 1.2, -2.0], dtype=torch.float64)
GOAL = torch.tensor([1.5, -0.4, -0.8, 1.1, -1.9, -0.6, 2.4], dtype=torch.float64)


# ------------------------------------------------------------------------------------------- numbers


@pytest.mark.parametrize("value", [25, np.int64(25), np.int32(25), torch.tensor(25), np.array(25)])
def test_integers_of_every_kind_are_integers(value):
    assert as_int(value, "n", minimum=0) == 25 and type(as_int(value, "n")) is int


@pytest.mark.parametrize("value", [0.5, np.float32(0.5), np.float64(0.5), torch.tensor(0.5), 1, np.int8(1)])
def test_reals_of_every_kind_are_reals(value):
    assert as_real(value, "x", minimum=0.0, open_minimum=True) == pytest.approx(float(value))


@pytest.mark.parametrize(
    "value",
    [True, np.bool_(True), torch.tensor(True), 1 + 0j, np.complex64(1), "3", None, torch.ones(2), 2.5],
)
def test_bools_complex_and_non_numbers_are_no_integers(value):
    with pytest.raises(ConfigError, match="n must be an integer"):
        as_int(value, "n")


@pytest.mark.parametrize("value", [False, 1j, torch.tensor(1j), float("nan"), float("inf"), "0.5"])
def test_bools_complex_nan_are_no_reals(value):
    with pytest.raises(ConfigError, match="x must be a finite real number"):
        as_real(value, "x")


def test_bounds_are_named():
    with pytest.raises(ConfigError, match=r"in \[0, 10\], got 11"):
        as_int(11, "n", minimum=0, maximum=10)
    with pytest.raises(ConfigError, match="> 0"):
        as_real(0.0, "x", minimum=0.0, open_minimum=True)
    with pytest.raises(ConfigError, match="≤ 1"):
        as_real(1.5, "x", maximum=1.0)


def test_plan_options_take_numpy_and_torch_scalars(robot):
    ball = [[0.58, -0.11, 1.03, 0.12]]
    a = kinlearn.plan(START, GOAL, obstacles=ball, refine_steps=1)
    for steps in (np.int64(1), torch.tensor(1)):
        b = kinlearn.plan(START, GOAL, obstacles=ball, refine_steps=steps)
        assert torch.equal(a.joints, b.joints)
    for bad in (-5, True, 2.0, torch.tensor(3.0), 10**9):  # refused with or without obstacles
        with pytest.raises(ConfigError, match="refine_steps"):
            kinlearn.plan(START, GOAL, refine_steps=bad)
    path = torch.stack((START, GOAL))
    t = time_parameterize(robot, path, velocity_scale=0.5)
    for scale in (np.float32(0.5), torch.tensor(0.5)):
        assert time_parameterize(robot, path, velocity_scale=scale).duration == pytest.approx(t.duration)
    assert len(time_parameterize(robot, path, samples=np.int64(7))) == 7
    with pytest.raises(ConfigError, match="velocity_scale"):
        time_parameterize(robot, path, velocity_scale=True)


# ---------------------------------------------------------------------------------------- work budgets


def test_timing_refuses_more_samples_than_its_budget_before_allocating(robot):
    path = torch.stack((START, GOAL))
    with pytest.raises(ConfigError, match="samples"):
        time_parameterize(robot, path, samples=10**9)
    with pytest.raises(ConfigError, match="MAX_SAMPLES"):
        time_parameterize(robot, path, dt=1e-9)
    with pytest.raises(ConfigError, match="larger velocity/acceleration limits"):
        time_parameterize(robot, path, velocity_limits=1e-12)
    assert len(time_parameterize(robot, path, samples=MAX_SAMPLES // 1000)) == MAX_SAMPLES // 1000


# ------------------------------------------------------------------------------ what readers believe


def _timed_json(robot, tmp_path, edit):
    import json

    tr = time_parameterize(robot, torch.stack((START, GOAL)), dt=0.1)
    obj = tr.to_dict()
    edit(obj)
    path = tmp_path / "t.json"
    path.write_text(json.dumps(obj))
    return path


@pytest.mark.parametrize(
    "edit",
    [
        lambda o: o["t"].reverse(),  # decreasing times
        lambda o: o["t"].__setitem__(0, 0.05),  # not from 0
        lambda o: o["q"][1].__setitem__(0, float("nan")),  # NaN position
        lambda o: o.__setitem__("duration", -1.0),
        lambda o: o["waypoint_times"].reverse(),
    ],
)
def test_from_json_refuses_times_that_do_not_increase_and_nan_positions(robot, tmp_path, edit):
    from kinlearn.errors import DatasetError
    from kinlearn.planning.timing import TimedTrajectory

    with pytest.raises(DatasetError, match="malformed"):
        TimedTrajectory.from_json(_timed_json(robot, tmp_path, edit))
    assert TimedTrajectory.from_json(_timed_json(robot, tmp_path, lambda o: None)).duration > 0


def test_judge_bounds_its_check_and_checks_what_it_is_given(robot):
    from kinlearn import Problem, judge
    from kinlearn.errors import ShapeError
    from kinlearn.planning.plan import MIN_CHECK_TRAVEL, Tolerance

    problem = Problem.make(robot, START[None], GOAL[None], obstacles=[[3.0, 3.0, 3.0, 0.1]])
    f = torch.linspace(0, 1, 5, dtype=torch.float64)[:, None]
    paths = (START + f * (GOAL - START))[None]
    assert bool(judge(problem, paths).success)
    with pytest.raises(ConfigError, match="max_travel"):  # it subdivided without end
        judge(problem, paths, max_travel=MIN_CHECK_TRAVEL / 1000)
    for bad in (float("nan"), -0.01, True):
        with pytest.raises(ConfigError, match="max_travel"):
            judge(problem, paths, max_travel=bad)
    with pytest.raises(ShapeError, match="found"):
        judge(problem, paths, found=torch.ones(3, dtype=torch.bool))
    with pytest.raises(ShapeError, match="found"):
        judge(problem, paths, found=torch.ones(1))
    for bad in (-0.01, float("nan")):
        with pytest.raises(ConfigError, match=r"Tolerance\.position"):
            Tolerance(position=bad)
    with pytest.raises(ConfigError, match="tolerance"):
        judge(problem, paths, tolerance=0.01)
    elsewhere = paths.clone()
    elsewhere[:, 0] += 0.2  # a path that starts elsewhere than the problem's start
    assert not bool(judge(problem, elsewhere).success)
    with pytest.raises(ConfigError, match="Problem"):
        judge((START, GOAL), paths)


def test_viewer_refuses_a_host_it_cannot_listen_on(robot):
    from kinlearn.viz import show_plan

    plan = kinlearn.plan(START, GOAL)
    for host in ("256.0.0.1", "no such host", "", None, "8.8.8.8"):  # not addresses of this machine
        with pytest.raises(ConfigError, match="host"):
            plan.show(host=host, block=False)
    with pytest.raises(ConfigError, match="port"):
        show_plan(robot, plan.joints, port=70000, block=False)


# -------------------------------------------------------------------------------------- output files


def test_every_output_file_gives_a_typed_error_for_a_path_it_cannot_be(robot, tmp_path):
    from kinlearn.collision import Scene
    from kinlearn.errors import OutputError

    plan = kinlearn.plan(START, GOAL)
    traj = plan.timed(dt=0.1)
    scene = Scene(torch.tensor([[0.5, 0.0, 0.5, 0.1]], dtype=torch.float64))
    (tmp_path / "a_file").write_text("x")
    (tmp_path / "a_folder").mkdir()
    writers = {
        "scene": lambda p: scene.save(p),
        "csv": traj.to_csv,
        "json": traj.to_json,
        "gif": lambda p: plan.animate(p, fps=50),
    }
    for name, write in writers.items():
        suffix = {"scene": ".npz"}.get(name, f".{name}")
        with pytest.raises(OutputError, match="it is a folder"):
            write(tmp_path / "a_folder")
        with pytest.raises(OutputError, match="is a file, not a folder"):
            write(tmp_path / "a_file" / f"out{suffix}")
        # A missing parent is made.
        assert write(tmp_path / "new" / name / f"out{suffix}").is_file()
    assert not list(tmp_path.rglob(".*.tmp"))


def test_a_full_disk_is_a_typed_error_that_says_so(tmp_path):
    """/dev/full fails every write with ENOSPC, as a full disk does; torch's own writer then reports
    "unexpected pos", which does not say the disk is full."""
    from kinlearn.errors import OutputError
    from kinlearn.io import atomic_write

    def python_write(tmp):
        with open("/dev/full", "wb") as f:
            f.write(b"x" * 100_000)

    if not Path("/dev/full").exists():
        pytest.skip("no /dev/full on this system")
    for write in (python_write, lambda tmp: torch.save({"w": torch.zeros(100_000)}, "/dev/full")):
        with pytest.raises(OutputError, match="the disk is full"):
            atomic_write(tmp_path / "model.pt", write)
        assert not (tmp_path / "model.pt").exists() and not list(tmp_path.glob(".*.tmp"))
    # A missing file that the write reads is not the output's fault: it stays what it is.
    with pytest.raises(FileNotFoundError):
        atomic_write(tmp_path / "copy.txt", lambda tmp: tmp.write_bytes((tmp_path / "nope").read_bytes()))


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root may write anywhere")
def test_no_permission_is_a_typed_error(tmp_path):
    from kinlearn.errors import OutputError

    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        with pytest.raises(OutputError, match="no permission"):
            kinlearn.plan(START, GOAL).timed(dt=0.1).to_csv(locked / "plan.csv")
    finally:
        locked.chmod(0o700)


def test_animate_checks_its_suffix_and_its_robot(tmp_path):
    plan = kinlearn.plan(START, GOAL)
    with pytest.raises(ConfigError, match=r"\.gif"):
        plan.animate(tmp_path / "x.png")
    assert not (tmp_path / "x.png").exists()
    q = kinlearn.load_robot("panda").sample(2, torch.Generator().manual_seed(0), dtype=torch.float64)
    panda = kinlearn.plan(q[0], q[1], robot="panda")
    with pytest.raises(ConfigError, match="for 'panda', not 'iiwa14'"):
        panda.animate(tmp_path / "p.gif", kinlearn.load_robot("iiwa14"))
    with pytest.raises(ConfigError, match="for 'panda', not 'iiwa14'"):
        panda.timed("iiwa14")


# -------------------------------------------------------------------------- degenerate and odd batches


def test_a_zero_length_move_plans_as_no_motion(robot):
    ball = [[3.0, 3.0, 3.0, 0.1]]  # far away: the obstacle mode, nothing in the way
    q2 = torch.stack((START, GOAL))
    for obstacles, steps in ((None, None), (ball, None), (ball, 5)):
        plan = kinlearn.plan(START, START, obstacles=obstacles, refine_steps=steps)
        assert torch.equal(plan.joints, START.expand_as(plan.joints))
        assert float((plan.ef - plan.ef[0]).abs().max()) == 0.0 and bool(plan.success)
        assert plan.timed().duration == 0.0
        # In a batch with a real move, the still one stays still and the other moves.
        both = kinlearn.plan(q2, torch.stack((START, START + 0.3)), obstacles=obstacles, refine_steps=steps)
        assert torch.equal(both.joints[0], plan.joints)
        assert float((both.joints[1] - both.joints[1, 0]).abs().max()) > 0.1


def test_joint_goal_and_obstacle_plans_do_not_depend_on_their_batch_mates(robot):
    """The same problem alone, at the NumPy batch size and at the torch one (> 16 plans)."""
    g = torch.Generator().manual_seed(5)
    starts, goals = robot.sample(17, g, dtype=torch.float64), robot.sample(17, g, dtype=torch.float64)
    ball = [[0.5, 0.1, 0.6, 0.15]]
    for obstacles in (None, ball):
        big = kinlearn.plan(starts, goals, obstacles=obstacles)
        small = kinlearn.plan(starts[:8], goals[:8], obstacles=obstacles)
        for i in (0, 5):
            alone = kinlearn.plan(starts[i], goals[i], obstacles=obstacles)
            for batch in (big, small):
                if obstacles is not None:  # the obstacle TM runs on each problem alone: bit for bit
                    assert torch.equal(alone.joints, batch.joints[i])
                assert torch.allclose(alone.joints, batch.joints[i], atol=1e-6, rtol=0)
                assert bool(alone.success) == bool(batch.success[i])


@pytest.mark.parametrize("mode", ["joints", "position", "obstacles", "refined"])
def test_an_empty_batch_gives_an_empty_plan(mode):
    e = torch.zeros(0, 7, dtype=torch.float64)
    kw = {
        "joints": dict(goal=e),
        "position": dict(goal_position=torch.zeros(0, 3)),
        "obstacles": dict(goal=e, obstacles=[[3.0, 3.0, 3.0, 0.1]]),
        "refined": dict(goal=e, obstacles=[[3.0, 3.0, 3.0, 0.1]], refine_steps=2),
    }[mode]
    plan = kinlearn.plan(e, **kw)
    assert plan.joints.shape[0] == 0 and plan.joints.shape[-1] == 7 and plan.success.shape == (0,)
    assert plan.ef.shape[:2] == plan.joints.shape[:2]


def test_problem_indexing_and_len_are_typed(robot):
    from kinlearn import Problem
    from kinlearn.errors import BatchIndexError

    one = Problem.make(robot, START, GOAL)
    with pytest.raises(BatchIndexError, match="no len"):
        len(one)
    with pytest.raises(BatchIndexError, match="cannot be indexed"):
        one[3]  # indexed a state's entries before
    many = Problem.make(robot, START.expand(2, 3, 7), GOAL.expand(2, 3, 7), obstacles=[[3.0, 3.0, 3.0, 0.1]])
    assert len(many) == 2 and len(list(many)) == 2  # iteration stops at the end (an IndexError)
    assert many[:, 1].batch_shape == (2,) and many[1, 2].batch_shape == ()
    assert torch.equal(many[-1, 0].start, many.start[-1, 0])
    for bad in (2, (0, 3), (slice(None), slice(None), 1), "a", 0.5):
        with pytest.raises(BatchIndexError):
            many[bad]


def test_baselines_take_a_robot_or_its_name(robot):
    from kinlearn import Problem, baselines
    from kinlearn.errors import UnknownRobotError

    problem = Problem.make(robot, START[None], GOAL[None], obstacles=[[3.0, 3.0, 3.0, 0.1]])
    for name in baselines.names():  # every registered baseline
        make = baselines.get(name)
        by_name, by_robot = make("iiwa14"), make(robot)
        assert by_name.robot.name == by_robot.robot.name == "iiwa14"
        if not make.one_at_a_time:  # (the searches need OMPL, or take a while)
            assert torch.equal(by_name.plan(problem).joints, by_robot.plan(problem).joints)
        with pytest.raises(UnknownRobotError):
            make("no-such-arm")
        with pytest.raises(ConfigError, match="robot"):
            make(7)


def test_obstacles_and_floors_must_be_real_numbers():
    from kinlearn.collision import Scene
    from kinlearn.errors import ObstacleError

    for obs in (
        np.ones((1, 4), dtype=bool),
        np.array([[3, 3, 3, 0.1]], dtype=complex),
        torch.ones(1, 4).bool(),
    ):
        with pytest.raises(ObstacleError, match="real numbers"):
            kinlearn.plan(START, GOAL, obstacles=obs)
    for floor in (True, np.bool_(False), 1j, torch.tensor(True)):
        with pytest.raises(ObstacleError, match="floor"):
            Scene(torch.tensor([[3.0, 3.0, 3.0, 0.1]]), floor=floor)
    assert Scene(torch.tensor([[3.0, 3.0, 3.0, 0.1]]), floor=np.float32(0.0)).floor is not None


@pytest.mark.parametrize("dtype", [torch.bfloat16, torch.float16])
def test_half_precision_plans_stay_within_the_limits_they_are_judged_by(robot, dtype):
    """Joints clamped to a limit in float64 rounded past it in bfloat16 (by 1.7e-3 rad) with success True."""
    g = torch.Generator().manual_seed(1)
    lo, hi = robot.limits(torch.float64)
    s = robot.sample(100, g, dtype=torch.float64, margin=0.01)
    e = robot.sample(100, g, dtype=torch.float64, margin=0.01)
    s[:, 0] = e[:, 0] = hi[0] - 0.01  # paths that run into joint 1's limit (a quarter crossed it before)
    plan = kinlearn.plan(s.to(dtype), e.to(dtype))
    assert plan.joints.dtype == dtype
    joints = plan.joints.double()
    assert bool(((joints >= lo) & (joints <= hi)).all())


def test_baseline_work_is_bounded(robot):
    from kinlearn.baselines import JointLine, cartesian_line, rrt_connect, trajectory_optimiser
    from kinlearn.planning.baselines import MAX_STEPS

    with pytest.raises(ConfigError, match="steps"):
        JointLine(robot, steps=MAX_STEPS + 1)
    problem = kinlearn.Problem.make(robot, START, GOAL)  # the function forms take states
    with pytest.raises(ConfigError, match="iterations"):
        cartesian_line(robot, problem.start, problem.goal, iterations=10**9)
    with pytest.raises(ConfigError, match="time_limit"):
        rrt_connect(robot, problem.start, problem.goal, time_limit=1e9)
    with pytest.raises(ConfigError, match="steps"):
        trajectory_optimiser(START, GOAL, kinlearn.Scene(torch.tensor([[3.0, 3.0, 3.0, 0.1]])), steps=10**9)
    assert JointLine(robot, steps=np.int64(5)).steps == 5


def test_the_dense_check_refuses_work_beyond_its_budget(robot):
    from kinlearn.collision import body_spheres, check_path
    from kinlearn.collision.check import MAX_CHECKED

    body = body_spheres(robot).double()
    path = torch.stack((START, GOAL))
    scene = kinlearn.Scene(torch.tensor([[3.0, 3.0, 3.0, 0.1]], dtype=torch.float64))
    with pytest.raises(ConfigError, match="MAX_CHECKED"):
        check_path(body, path, scene, max_travel=1e-9)  # 1e9 configurations and more
    assert bool(check_path(body, path, scene).collision_free) and MAX_CHECKED >= 1_000_000
