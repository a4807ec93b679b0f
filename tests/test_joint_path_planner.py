"""The joint-path TM and its planner: goal states reached, limits kept, honest outcome, fast path
agreeing with the model, position goals, the training domain, bad input."""

import copy
import dataclasses
import pickle
import warnings

import numpy as np
import pytest
import torch

import kinlearn
from kinlearn import kinematics, load_robot
from kinlearn.data.endpoints import EndpointConfig, make_endpoints, workspace_box
from kinlearn.errors import ConfigError, DomainError, DomainWarning, DTypeError, ShapeError
from kinlearn.models.forward_inverse import (
    AnalyticFM,
    AnalyticIM,
    ForwardModel,
    LearnedFM,
    fm_config,
)
from kinlearn.models.joint_path import JointPathConfig, JointPathModel, densify
from kinlearn.planning.inference import CompiledPathModel
from kinlearn.planning.plan import Plan
from kinlearn.planning.planner import MAX_STEP, Planner
from kinlearn.training.joint_path import PathTrainConfig, train_path_model
from kinlearn.training.tm import tm_preset, train_tm

ALL_ROBOTS = ("iiwa14", "panda", "ur5", "xarm7", "z1")


@pytest.fixture(scope="module")
def trained(robot, tmp_path_factory):
    """A tiny joint-path TM trained through the analytic FM (seconds)."""
    run = tmp_path_factory.mktemp("jp")
    cfg = PathTrainConfig(
        fm="analytic", iterations=30, batch_size=64, checkpoint_every=10, model={"hidden": (64, 64)}
    )
    tm = train_path_model(cfg, run, progress=False)
    return run, tm


@pytest.fixture(scope="module")
def planner(robot, trained):
    return Planner(robot, trained[1], AnalyticFM(robot), AnalyticIM(robot, iterations=3))


@pytest.fixture(scope="module")
def workspace_pairs():
    return make_endpoints(EndpointConfig(n=256, seed=3, preset="workspace", range_fraction=0.9))


def test_workspace_endpoints_cover_the_joint_range(robot):
    pairs = make_endpoints(EndpointConfig(n=4000, seed=1, preset="workspace", range_fraction=0.9))
    lo, hi = workspace_box(robot, 0.9)
    q = torch.cat((pairs.start[:, :7], pairs.goal[:, :7])).double()
    assert bool(((q >= lo - 1e-6) & (q <= hi + 1e-6)).all())
    # Uniform across the box: every joint reaches within 5% of both ends of it.
    span = hi - lo
    assert bool((q.min(0).values < lo + 0.05 * span).all()) and bool(
        (q.max(0).values > hi - 0.05 * span).all()
    )
    ef = kinematics(robot).position(pairs.start[:, :7].double())
    assert torch.allclose(ef.float(), pairs.start[:, 7:], atol=1e-5)


def test_joint_goals_are_reached_exactly_and_limits_hold(planner, workspace_pairs, robot):
    plan = planner.plan(workspace_pairs.start, workspace_pairs.goal)
    assert plan.joints.shape == (256, 12, 7) and plan.waypoints.shape == (256, 10, 3)
    assert torch.equal(plan.joints[:, 0], workspace_pairs.start[:, :7])
    assert torch.equal(plan.joints[:, -1], workspace_pairs.goal[:, :7])
    assert float(plan.joint_error.max()) == 0.0 and float(plan.goal_error.max()) < 1e-5
    assert bool(plan.success.all())
    lo, hi = robot.limits(torch.float32)
    assert bool(((plan.joints >= lo - 1e-6) & (plan.joints <= hi + 1e-6)).all())
    assert torch.allclose(plan.ef.double(), kinematics(robot).position(plan.joints.double()), atol=1e-5)


def test_limits_hold_even_when_the_model_asks_for_more(robot):
    """A model whose corrections leave the limits is clamped: every returned configuration is inside."""
    tm = JointPathModel(JointPathConfig.for_robot(robot, hidden=(16,)))
    with torch.no_grad():
        tm.net[-1].bias.fill_(3.0)  # corrections of 3 half-ranges
    p = Planner(robot, tm)
    q = robot.sample((100, 2), torch.Generator().manual_seed(0))
    plan = p.plan(q[:, 0], q[:, 1])
    lo, hi = robot.limits(torch.float32)
    assert bool(((plan.joints >= lo) & (plan.joints <= hi)).all())
    assert bool(plan.success.all())


def test_small_and_large_batches_agree(planner, workspace_pairs):
    """Batches of up to SMALL_BATCH plans run in NumPy, larger ones in torch: the same plans."""
    big = planner.plan(workspace_pairs.start, workspace_pairs.goal)
    for i in (0, 7, 100):
        one = planner.plan(workspace_pairs.start[i], workspace_pairs.goal[i])
        assert torch.allclose(one.joints, big.joints[i], atol=1e-5)
        assert torch.allclose(one.ef, big.ef[i], atol=1e-5)


def test_plan_is_deterministic_and_follows_dtype(planner, workspace_pairs):
    a = planner.plan(workspace_pairs.start[:8], workspace_pairs.goal[:8])
    b = planner.plan(workspace_pairs.start[:8], workspace_pairs.goal[:8])
    for f in ("joints", "ef", "waypoints", "goal_error", "success"):
        assert torch.equal(getattr(a, f), getattr(b, f)), f
    one = planner.plan(workspace_pairs.start[0, :7].double(), workspace_pairs.goal[0, :7].double())
    assert (
        one.joints.shape == (12, 7) and one.joints.dtype == torch.float64 and one.success.dtype == torch.bool
    )
    grid = planner.plan(
        workspace_pairs.start[:6].reshape(2, 3, 10), workspace_pairs.goal[:6].reshape(2, 3, 10)
    )
    assert grid.joints.shape == (2, 3, 12, 7) and grid.success.shape == (2, 3)
    lists = planner.plan(workspace_pairs.start[:2].tolist(), workspace_pairs.goal[:2].numpy())
    assert lists.joints.shape == (2, 12, 7)


@pytest.mark.parametrize("modes", [0, 4])
def test_compiled_path_model_matches_the_torch_model(robot, modes):
    tm = JointPathModel(JointPathConfig.for_robot(robot, hidden=(32, 32), modes=modes)).double()
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():
        for p in tm.net.parameters():
            p.copy_(torch.randn(p.shape, generator=g, dtype=p.dtype) * 0.3)
        tm.in_mean.normal_(generator=g)
        tm.in_std.uniform_(0.5, 2.0, generator=g)
    q = robot.sample((2, 20), g, dtype=torch.float64)
    ef = kinematics(robot).position(q)
    with torch.no_grad():
        out = tm(torch.cat((q[0], ef[0]), -1), torch.cat((q[1], ef[1]), -1))
    joints, wp = CompiledPathModel(tm, dtype=np.float64)(
        q[0].numpy(), ef[0].numpy(), q[1].numpy(), ef[1].numpy()
    )
    assert np.abs(joints - out.joints.numpy()).max() < 1e-10
    assert np.abs(wp - out.ef.numpy()).max() < 1e-12
    joints32, _ = CompiledPathModel(tm)(q[0].numpy(), ef[0].numpy(), q[1].numpy(), ef[1].numpy())
    assert np.abs(joints32 - out.joints.numpy()).max() < 1e-4  # float32 arithmetic, the planner's default


def test_position_goals_are_reached_or_flagged(planner, workspace_pairs, robot):
    start = workspace_pairs.start[:32, :7]
    target = workspace_pairs.goal[:32, 7:]
    plan = planner.plan(start, goal_position=target)
    assert plan.joints.shape == (32, 12, 7)
    assert torch.equal(plan.target, target)
    err = (kinematics(robot).position(plan.joints[:, -1].double()) - target.double()).norm(dim=-1)
    assert torch.allclose(plan.goal_error.double(), err, atol=1e-6)
    assert bool(torch.isnan(plan.joint_error).all())
    assert torch.equal(plan.success, plan.goal_error <= 0.01)
    assert float(plan.success.float().mean()) > 0.8  # analytic IM: most reachable goals are hit
    # The same through the (..., 3) goal form.
    assert torch.allclose(planner.plan(start[:4], target[:4]).joints, plan.joints[:4], atol=1e-5)
    # An unreachable target (5 m away) is a failure the plan says so, not a silent plan.
    far = planner.plan(start[:2], goal_position=torch.tensor([5.0, 0.0, 0.0]).expand(2, 3))
    assert not bool(far.success.any()) and bool((far.goal_error > 3.0).all())
    lo, hi = robot.limits(torch.float32)
    assert bool(((far.joints >= lo - 1e-6) & (far.joints <= hi + 1e-6)).all())


def test_position_goals_need_models(robot, trained):
    with pytest.raises(ConfigError, match="FM and IM"):
        Planner(robot, trained[1]).plan(torch.zeros(7), goal_position=[0.5, 0.0, 0.5])


def test_plan_rejects_bad_input(planner):
    z = torch.zeros(7)
    with pytest.raises(DTypeError):
        planner.plan("start", z)
    with pytest.raises(DTypeError):
        planner.plan(torch.zeros(7, dtype=torch.bool), z)
    with pytest.raises(DTypeError):
        planner.plan(torch.zeros(7, dtype=torch.complex64), z)
    with pytest.raises(ConfigError, match="exactly one"):
        planner.plan(z, z, goal_position=[0.5, 0.0, 0.5])
    with pytest.raises(ConfigError, match="exactly one"):
        planner.plan(z)
    with pytest.raises(ShapeError, match=r"\(\.\.\., 3\)"):
        planner.plan(z, goal_position=[0.5, 0.0])
    with pytest.raises(ShapeError, match="broadcast"):
        planner.plan(torch.zeros(3, 7), torch.zeros(2, 7))
    with pytest.raises(kinlearn.NonFiniteError):
        planner.plan(z, goal_position=[float("nan"), 0.0, 0.5])


def test_unbatched_plan_cannot_be_indexed(planner):
    plan = planner.plan(torch.zeros(7), torch.full((7,), 0.3))
    with pytest.raises(ShapeError, match="single plan"):
        plan[0]
    batch = planner.plan(torch.zeros(3, 7), torch.full((3, 7), 0.3))
    assert batch[1].joints.shape == (12, 7) and len(batch) == 3
    with pytest.raises(ShapeError):
        batch[5]
    assert "1/1 plans succeeded" in plan.summary()


def test_domain_warning_and_strict_error(robot, tmp_path):
    """A paper-task planner warns on starts far from its training starts; strict=True raises."""
    pairs = make_endpoints(EndpointConfig(n=32, seed=5))
    train_tm(
        tm_preset("default", fm="analytic", im="analytic", epochs=1, batch_size=16),
        tmp_path,
        pairs,
        progress=False,
    )
    p = Planner.load(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        p.plan(pairs.start[:2], pairs.goal[:2])  # in the domain: no warning
    far = torch.tensor([-2.5, -1.5, 2.0, 1.5, -2.0, -1.5, 2.5])
    with pytest.warns(DomainWarning, match="outside the domain"):
        p.plan(far, pairs.goal[0])
    with pytest.raises(DomainError, match="strict=False"):
        p.plan(far, pairs.goal[0], strict=True)


def test_densify_keeps_every_step_within_the_bound(robot):
    q = robot.sample((50, 12), torch.Generator().manual_seed(4), dtype=torch.float64)
    dense, m = densify(q, MAX_STEP)
    assert torch.equal(dense[:, ::m], q)
    assert float((dense[:, 1:] - dense[:, :-1]).abs().max()) <= MAX_STEP + 1e-12
    dense3, m3 = densify(q, MAX_STEP, multiple_of=3)
    assert m3 % 3 == 0 and m3 >= m and torch.equal(dense3[:, ::m3], q)


def test_parallel_ef_along_equals_the_step_by_step_rollout(robot):
    """The difference FM's telescoped rollout is the sequential rollout of its own steps."""
    fm = LearnedFM(fm_config("iiwa14", "improved", fk_hidden=(32, 32))).double()
    q = robot.sample((4, 9), torch.Generator().manual_seed(6), dtype=torch.float64) * 0.1
    path, _ = densify(q, MAX_STEP)
    ef0 = torch.randn(4, 3, dtype=torch.float64)
    with torch.no_grad():
        fast = fm.ef_along(path, ef0)
        slow = ForwardModel.ef_along(fm, path, ef0)
        assert torch.allclose(fast, slow, atol=1e-9)
        assert torch.allclose(fm.ef_along(path, ef0, every=3), slow[:, ::3], atol=1e-9)
    exact = AnalyticFM(robot).ef_along(path, ef0)
    assert torch.allclose(exact, kinematics(robot).position(path), atol=1e-12)


def test_training_resumes_bit_identically(tmp_path, monkeypatch):
    """Interrupted after its checkpoint at iteration 8, a run resumes and ends bit-identical."""
    import kinlearn.training.joint_path as tp

    cfg = PathTrainConfig(
        fm="analytic", iterations=12, batch_size=32, checkpoint_every=4, model={"hidden": (16,)}
    )
    straight = train_path_model(cfg, tmp_path / "a", progress=False)
    real, calls = tp.path_loss, []

    def failing(*args, **kwargs):
        calls.append(1)
        if len(calls) == 10:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(tp, "path_loss", failing)
    with pytest.raises(KeyboardInterrupt):
        train_path_model(cfg, tmp_path / "b", progress=False)
    monkeypatch.setattr(tp, "path_loss", real)
    resumed = train_path_model(cfg, tmp_path / "b", progress=False)
    for (k, v), (_, w) in zip(straight.state_dict().items(), resumed.state_dict().items(), strict=True):
        assert torch.equal(v, w), k
    assert not list((tmp_path / "b").glob("*.tmp"))


def test_path_train_config_checks(robot):
    with pytest.raises(ConfigError, match="fm_checkpoint"):
        PathTrainConfig(fm="learned")
    with pytest.raises(ConfigError, match="lr"):
        PathTrainConfig(fm="analytic", lr=-1.0)
    with pytest.raises(ConfigError, match="iterations"):
        PathTrainConfig(fm="analytic", iterations=0)
    with pytest.raises(ConfigError, match="modes"):
        JointPathConfig.for_robot(robot, modes=-1)


def test_saved_planner_folder_loads(trained, robot):
    run, tm = trained
    p = Planner.load(run)
    assert isinstance(p.tm, JointPathModel)
    q = robot.sample((2, 3), torch.Generator().manual_seed(1))
    assert torch.equal(p.plan(q[0], q[1]).joints, Planner(robot, tm).plan(q[0], q[1]).joints)


def test_plan_timed_respects_the_robots_limits(planner, robot):
    plan = planner.plan(torch.zeros(7), torch.full((7,), 0.4))
    traj = plan.timed()
    assert traj.q.shape[1] == 7 and traj.t[0] == 0.0 and traj.duration > 0
    vel = np.asarray(robot.velocity_limits)
    assert (np.abs(traj.qd) <= vel * (1 + 1e-5)).all()
    assert np.allclose(traj.q[-1], plan.joints[-1].numpy(), atol=1e-6)
    with pytest.raises(ShapeError, match="single plan"):
        planner.plan(torch.zeros(2, 7), torch.full((2, 7), 0.4)).timed()


def test_plan_show_holds_the_plan(planner):
    pytest.importorskip("viser")
    plan = planner.plan(torch.zeros(7), torch.full((7,), 0.4))
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    viewer = plan.show(port=port, block=False)
    try:
        names = viewer.node_names()
        assert any(n.startswith("/waypoints/") for n in names) and "/path/executed" in names
    finally:
        viewer.close()


def test_plan_command(trained, robot, tmp_path, capsys):
    from kinlearn.cli.main import main
    from kinlearn.models.forward_inverse import save_model

    run, _ = trained
    folder = tmp_path / "planner"
    folder.mkdir()
    (folder / "tm.pt").write_bytes((run / "tm.pt").read_bytes())
    save_model(AnalyticFM(robot), folder / "fm.pt")
    save_model(AnalyticIM(robot, iterations=3), folder / "im.pt")
    start, goal = "-0.3,0.45,0,-1.35,0,1.05,0", "0.6,1.1,0,-0.7,0,0.9,0"  # a negative first value
    timed = tmp_path / "traj.csv"
    assert (
        main(["plan", "--model", str(folder), "--start", start, "--goal", goal, "--timed", str(timed)]) == 0
    )
    out = capsys.readouterr().out
    assert "1/1 plans succeeded" in out and "timed trajectory" in out
    rows = timed.read_text().splitlines()
    assert len(rows) > 10 and rows[0].startswith("t")
    # A position goal 5 m away cannot be reached: the table says so and the exit status is 1.
    assert main(["plan", "--model", str(folder), "--start", start, "--goal-position", "5,0,0"]) == 1
    assert "0/1 plans succeeded" in capsys.readouterr().out
    assert main(["plan", "--model", str(folder), "--start", start, "--goal", "0,0,0,9,0,0,0"]) == 2
    assert "iiwa_joint_4" in capsys.readouterr().err
    assert (
        main(
            [
                "plan",
                "--model",
                str(folder),
                "--start",
                start,
                "--goal",
                goal,
                "--timed",
                str(tmp_path / "x.txt"),
            ]
        )
        == 2
    )


def test_train_planner_command_makes_a_planner_folder(tmp_path, capsys):
    from kinlearn.cli.main import main

    run = tmp_path / "p"
    args = ["train-planner", "--analytic-fm", "--iterations", "4", "--batch-size", "16", "--hidden", "16"]
    assert main([*args, "--heldout", "16", "--run-dir", str(run), "--no-progress"]) == 0
    assert "goal state reached" in capsys.readouterr().out
    assert {"tm.pt", "fm.pt", "config.json"} <= {p.name for p in run.iterdir()}
    planner = Planner.load(run)
    assert isinstance(planner.tm, JointPathModel) and isinstance(planner.fm, AnalyticFM)
    # A finished run is not silently retrained or replaced.
    assert main([*args, "--run-dir", str(run), "--no-progress"]) == 2
    assert "--resume" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:  # argparse rejects the option before the command runs
        main([*args, "--hidden", "0", "--run-dir", str(tmp_path / "q")])
    assert exc.value.code == 2 and "integers ≥ 1" in capsys.readouterr().err


def test_readme_quick_start_runs(tmp_path, monkeypatch):
    """The README's Python quick start runs as written (but for the browser view)."""
    import re
    from pathlib import Path

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    code = re.search(r"## Quick start\s+```python\n(.*?)```", readme, re.S).group(1)
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    exec(compile(code, "README.md", "exec"), namespace)
    plan = namespace["plan"]  # the obstacle example, deterministic: cleared, and timed as executed
    assert bool(plan.success) and bool(plan.collision_free) and plan.stage != "none"
    assert namespace["traj"].duration > 0 and namespace["traj"].verified


def test_plan_takes_a_robot_object(robot, workspace_pairs):
    """kinlearn.plan(..., robot=Robot) uses that robot's shipped planner."""
    plan = kinlearn.plan(workspace_pairs.start[:2, :7], workspace_pairs.goal[:2, :7], robot=robot)
    assert plan.joints.shape[0] == 2 and plan.robot == "iiwa14"
    panda = load_robot("panda")
    q = panda.sample(2, torch.Generator().manual_seed(0), dtype=torch.float64)
    assert kinlearn.plan(q[0], q[1], robot=panda).robot == "panda"


@pytest.mark.parametrize("name", ["iiwa14", "ur5"])
def test_the_batch1_free_space_entry_plans_what_the_general_path_plans(name, monkeypatch):
    """One problem as two joint vectors takes the compiled batch-1 entry; the same problem through the
    general path (the entry turned off) gives the same plan, field by field, to the bit, in every input
    dtype; ends beyond the limits or not apart are left to the general path, which explains them."""
    from kinlearn.errors import JointLimitError
    from kinlearn.planning.planner import DEFAULT_CHECKPOINTS

    planner, general = (Planner.load(DEFAULT_CHECKPOINTS / name) for _ in range(2))
    robot = planner.robot
    q = robot.sample(8, torch.Generator().manual_seed(3), dtype=torch.float64).numpy()
    monkeypatch.setattr(general, "_batch1_free", lambda start, goal: None)
    calls = []
    real = planner._batch1_free

    def spy(start, goal):
        out = real(start, goal)
        calls.append(out is not None)
        return out

    monkeypatch.setattr(planner, "_batch1_free", spy)
    for a, b in zip(q[::2], q[1::2], strict=True):
        for cast in (lambda x: x, torch.from_numpy, lambda x: torch.from_numpy(x).float()):
            lean, full = planner.plan(cast(a), cast(b)), general.plan(cast(a), cast(b))
            for field in (f for f in Plan._BATCHED if f != "collision_free"):  # None in free space
                x, y = getattr(lean, field), getattr(full, field)
                assert x.dtype == y.dtype and x.shape == y.shape, field
                assert torch.equal(x, y) or (x.isnan().all() and y.isnan().all()), field
            assert lean.stage == full.stage and lean.collision_free is None
            assert lean.robot == full.robot and lean.tolerance == full.tolerance and lean.scene is None
    assert all(calls) and len(calls) == 12
    # its tensors made when first read, the plan reads, copies, pickles and replaces as any other
    fresh = planner.plan(q[0], q[1])
    assert "joints" not in vars(fresh)
    for other in (copy.copy(fresh), copy.deepcopy(fresh), pickle.loads(pickle.dumps(fresh))):
        for field in (f for f in Plan._BATCHED if f != "collision_free"):
            assert torch.equal(getattr(other, field), getattr(fresh, field)), field
    moved = dataclasses.replace(fresh, stage="refine")
    assert moved.stage == "refine" and torch.equal(moved.joints, fresh.joints)
    assert "Plan(" in repr(fresh) and len(fresh.timed().t) > 1
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        fresh.nothing  # noqa: B018
    calls.clear()
    beyond = q[0].copy()
    beyond[0] = robot.upper[0] + 0.1
    with pytest.raises(JointLimitError):
        planner.plan(beyond, q[1])
    still = planner.plan(q[0], q[0])
    assert calls == [False, False] and bool(still.success) and torch.equal(still.joints[-1], still.joints[0])
