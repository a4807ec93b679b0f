"""Planner and plan(): determinism, input validation, the shipped checkpoint, another robot."""

import pytest
import torch

import kinlearn
from kinlearn import JointLimitError, NonFiniteError, ShapeError, kinematics, load_robot
from kinlearn.data.babbling import BabblingConfig, babble
from kinlearn.data.endpoints import EndpointConfig, make_endpoints
from kinlearn.errors import CheckpointError, ConfigError, StateError
from kinlearn.models.forward_inverse import AnalyticFM, AnalyticIM, fm_config, im_config
from kinlearn.models.trajectory import TMConfig, TrajectoryModel
from kinlearn.planning.planner import DEFAULT_CHECKPOINTS, Planner
from kinlearn.training.forward_inverse import train_config, train_fm, train_im
from kinlearn.training.tm import tm_preset, train_tm


@pytest.fixture(scope="module")
def pairs():
    return make_endpoints(EndpointConfig(n=64, seed=5))


@pytest.fixture(scope="module")
def analytic_planner(robot, pairs, tmp_path_factory):
    run = tmp_path_factory.mktemp("tm")
    cfg = tm_preset("default", fm="analytic", im="analytic", epochs=2, batch_size=16)
    train_tm(cfg, run, pairs, progress=False)
    return Planner.load(run)


def test_plan_shapes_and_joint_path(analytic_planner, pairs, robot):
    plan = analytic_planner.plan(pairs.start[:5], pairs.goal[:5])
    assert plan.waypoints.shape == (5, 10, 3)
    assert plan.actions.shape == (5, 11, 7)
    assert plan.joints.shape == (5, 12, 7) and plan.ef.shape == (5, 12, 3)
    assert torch.equal(plan.joints[:, 0], pairs.start[:5, :7])
    assert torch.allclose(plan.joints[:, 1:], plan.joints[:, :1] + plan.actions.cumsum(1), atol=1e-6)
    assert torch.allclose(plan.ef, kinematics(robot).position(plan.joints), atol=1e-6)


def test_plan_is_deterministic_bit_for_bit(analytic_planner, pairs):
    a = analytic_planner.plan(pairs.start, pairs.goal)
    b = analytic_planner.plan(pairs.start, pairs.goal)
    for f in ("waypoints", "actions", "joints", "ef"):
        assert torch.equal(getattr(a, f), getattr(b, f)), f


def test_plan_accepts_joints_states_batches_and_float64(analytic_planner, pairs):
    full = analytic_planner.plan(pairs.start[:3], pairs.goal[:3])
    joints = analytic_planner.plan(pairs.start[:3, :7], pairs.goal[:3, :7])
    assert torch.allclose(full.waypoints, joints.waypoints, atol=1e-5)
    one = analytic_planner.plan(pairs.start[0, :7].double(), pairs.goal[0, :7].double())
    assert one.waypoints.shape == (10, 3) and one.joints.dtype == torch.float64
    grid = analytic_planner.plan(pairs.start[:6].reshape(2, 3, 10), pairs.goal[:6].reshape(2, 3, 10))
    assert grid.joints.shape == (2, 3, 12, 7)
    assert torch.allclose(
        grid.waypoints.reshape(6, 10, 3), analytic_planner.plan(pairs.start[:6], pairs.goal[:6]).waypoints
    )
    assert analytic_planner.plan(pairs.start[:2].tolist(), pairs.goal[:2].numpy()).waypoints.shape == (
        2,
        10,
        3,
    )


def test_plan_rejects_bad_input(analytic_planner, pairs):
    s, g = pairs.start[:2].clone(), pairs.goal[:2].clone()
    with pytest.raises(ShapeError, match=r"\(\.\.\., 10\).*\(\.\.\., 7\)"):
        analytic_planner.plan(s[:, :6], g)
    bad = s.clone()
    bad[0, 3] = float("nan")
    with pytest.raises(NonFiniteError):
        analytic_planner.plan(bad, g)
    out = s.clone()
    out[1, 1] = 3.0  # joint 2 allows ±2.0944 rad
    with pytest.raises(JointLimitError, match="iiwa_joint_2"):
        analytic_planner.plan(out, g)
    lying = g.clone()
    lying[0, 7] += 0.05  # end effector 5 cm away from FK of its joints
    with pytest.raises(StateError, match="FK"):
        analytic_planner.plan(s, lying)


def test_planner_refuses_models_of_another_robot(robot, pairs):
    panda = load_robot("panda")
    tm = TrajectoryModel(TMConfig())
    with pytest.raises(ConfigError, match="panda"):
        Planner(panda, tm, AnalyticFM(panda), AnalyticIM(panda))
    with pytest.raises(ConfigError, match="iiwa14"):
        Planner(robot, tm, AnalyticFM(robot), AnalyticIM(panda))


def test_load_checks_robot(analytic_planner, tmp_path, pairs):
    run = tmp_path / "run"
    train_tm(tm_preset("default", fm="analytic", im="analytic", epochs=1), run, pairs, progress=False)
    with pytest.raises(CheckpointError, match="panda"):
        Planner.load(run, robot="panda")
    with pytest.raises(ConfigError, match=r"no tm\.pt"):
        Planner.load(tmp_path / "empty")


def test_corrupt_checkpoint(tmp_path):
    (tmp_path / "tm.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(CheckpointError, match="not a readable"):
        Planner.load(tmp_path)


def test_shipped_checkpoint_loads_and_plans(pairs, robot):
    """The shipped planner reaches the goal *state* on the paper's task too, and says so."""
    assert (DEFAULT_CHECKPOINTS / "iiwa14" / "tm.pt").is_file()
    plan = kinlearn.plan(pairs.start, pairs.goal)
    assert plan.joints.shape == (64, 12, 7) and plan.waypoints.shape == (64, 10, 3)
    assert torch.equal(plan.joints, kinlearn.plan(pairs.start, pairs.goal).joints)
    assert torch.isfinite(plan.ef).all()
    from kinlearn.evaluation.metrics import plan_metrics

    m = plan_metrics(plan, robot)
    assert float(m["state_success"].mean()) >= 0.95 and bool(plan.success.all())
    assert float(m["limit_violation"].sum()) == 0
    assert float(m["executed_sharp_turn"].mean()) <= 0.1


def test_a_robot_without_a_shipped_planner_is_told_so(tmp_path, monkeypatch):
    import kinlearn.planning.planner as planner_mod

    (tmp_path / "iiwa14").mkdir()
    monkeypatch.setattr(planner_mod, "DEFAULT_CHECKPOINTS", tmp_path)
    planner_mod._default_planner.cache_clear()
    try:
        with pytest.raises(ConfigError, match="ships no planner for 'panda'"):
            kinlearn.plan(torch.zeros(7), torch.full((7,), -1.0), robot="panda")
    finally:
        planner_mod._default_planner.cache_clear()


def test_tiny_learned_pipeline_for_panda(tmp_path):
    """babble → FM/IM → endpoints → TM → plan, all for a different 7-joint arm."""
    data = babble(BabblingConfig(robot="panda", walkers=200, steps=50, seed=0))
    models = tmp_path / "models"
    train_fm(data, fm_config("panda", "tiny"), train_config("fm", "tiny", progress=False), run_dir=models)
    train_im(data, im_config("panda", "tiny"), train_config("im", "tiny", progress=False), run_dir=models)
    pairs = make_endpoints(EndpointConfig(robot="panda", n=48, seed=1))
    run = tmp_path / "tm"
    cfg = tm_preset("default", robot="panda", models_dir=str(models), epochs=2, batch_size=16)
    train_tm(cfg, run, pairs, progress=False)
    planner = Planner.load(run)
    assert planner.robot.name == "panda"
    plan = planner.plan(pairs.start[:4], pairs.goal[:4])
    assert plan.joints.shape == (4, 12, 7) and torch.isfinite(plan.ef).all()


def test_rollout_options_are_checked(robot):
    tm = TrajectoryModel(TMConfig())
    with pytest.raises(ConfigError, match="refine"):
        Planner(robot, tm, AnalyticFM(robot), AnalyticIM(robot), refine=-1)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_plans_follow_the_inputs_device_and_dtype():
    planner = Planner.default("iiwa14")
    gen = torch.Generator().manual_seed(3)
    start, goal = planner.robot.sample((4,), gen, margin=0.1), planner.robot.sample((4,), gen, margin=0.1)
    on_cpu = planner.plan(start, goal)
    for dtype in (torch.float32, torch.float64):
        on_gpu = planner.plan(start.to("cuda", dtype), goal.to("cuda", dtype))
        assert on_gpu.joints.device.type == "cuda" and on_gpu.joints.dtype == dtype
        torch.testing.assert_close(on_gpu.joints.cpu().double(), on_cpu.joints.double(), atol=1e-6, rtol=0)
        assert torch.equal(on_gpu.success.cpu(), on_cpu.success)


def test_the_default_planner_is_shared_and_options_make_a_new_one():
    shared = Planner.default("iiwa14")
    assert Planner.default("iiwa14") is shared and shared.retreat
    alone = Planner.default("iiwa14", retreat=False)
    assert alone is not shared and not alone.retreat and shared.retreat
    assert alone.obstacle_tm is not None and alone.robot.name == "iiwa14"
    with pytest.raises(ConfigError, match="ships no planner"):
        Planner.default("no_such_arm", retreat=False)
