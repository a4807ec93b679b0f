"""Planning around obstacles: the plan's collision verdict, bad obstacles, colliding starts."""

from __future__ import annotations

import dataclasses
import pickle
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from kinlearn.body.kinematics import kinematics
from kinlearn.collision import Scene, check_path
from kinlearn.data.problems import ProblemSet
from kinlearn.errors import ConfigError, ObstacleError, ShapeError
from kinlearn.models.obstacle_path import ObstaclePathConfig, ObstaclePathModel
from kinlearn.planning.planner import Planner

BENCHMARK = Path(__file__).resolve().parents[1] / "benchmarks" / "data" / "obstacle_problems_heldout.npz"


@pytest.fixture(scope="module")
def planner(robot):
    """The shipped planner's models with a small untrained obstacle TM: the verdicts must hold for any TM."""
    base = Planner.default("iiwa14")
    torch.manual_seed(0)
    otm = ObstaclePathModel(
        ObstaclePathConfig.for_robot(robot, hidden=(32, 32), encoder=(16, 16), candidates=4)
    )
    with torch.no_grad():
        for p in otm.trunk[-1].parameters():
            p.normal_(0.0, 0.2)
    return Planner(robot, base.tm, base.fm, base.im, obstacle_tm=otm)


@pytest.fixture(scope="module")
def problems():
    ps = ProblemSet.load(BENCHMARK)
    return ps[torch.arange(0, len(ps), 51)]  # 20 problems from every family


def test_collision_free_agrees_with_the_dense_check(planner, problems):
    plan = planner.plan(problems.start, problems.goal, obstacles=problems.scene)
    check = check_path(planner.body, plan.joints.double(), problems.scene)
    assert torch.equal(plan.collision_free, check.collision_free)
    assert not (plan.success & ~plan.collision_free).any()
    assert plan.collision_free.any()  # the straight line is among the candidates; easy problems pass
    # The plan starts and ends at the given joints.
    assert torch.allclose(plan.joints[:, 0], problems.start)
    assert torch.allclose(plan.joints[:, -1], problems.goal)


def test_shipped_planner_batch_one_flags_agree_with_the_dense_check():
    """The shipped planner at batch 1 (its compiled path: packed scene, kernel verdicts, judge's fast path)
    on 60 held-out problems of every family, with and without the retreat stage: each plan's collision_free is torch check_path's verdict of
    its joint path, and success is the judged rule (goal reached and free)."""
    shipped = Planner.default("iiwa14")
    ps = ProblemSet.load(BENCHMARK)
    idx = torch.arange(0, len(ps), 17).tolist()
    joints, flags, success = [], [], []
    # The fixed-time stages, and the network alone (which leaves more colliding: both verdicts are met)
    for planner in (shipped, Planner.default("iiwa14", retreat=False)):
        for i in idx:
            start, goal, scene = ps.problem(i)
            one = planner.plan(start, goal, obstacles=scene, refine_steps=0)
            joints.append(one.joints)
            flags.append(bool(one.collision_free))
            success.append(bool(one.success))
    # one by one: a retreat-stage plan has more knots than the proposals' (its vias)
    dense = [
        bool(check_path(shipped.body, j, ps.scene[i]).collision_free)
        for j, i in zip(joints, idx + idx, strict=True)
    ]
    assert dense == flags
    assert success == flags  # joint goals are reached exactly: success is the verdict
    assert 0 < sum(flags) < len(flags)


def test_batch_one_gives_the_batch_verdict(planner, problems):
    plan = planner.plan(problems.start, problems.goal, obstacles=problems.scene)
    for i in (0, 7, 13):
        start, goal, scene = problems.problem(i)
        one = planner.plan(start, goal, obstacles=scene)
        assert one.collision_free.shape == ()
        assert bool(one.collision_free) == bool(plan.collision_free[i])
        assert bool(check_path(planner.body, one.joints, scene).collision_free) == bool(one.collision_free)
        # its tensors are made when first read: it pickles and replaces as any plan
        again = pickle.loads(pickle.dumps(planner.plan(start, goal, obstacles=scene)))
        assert torch.equal(again.joints, one.joints) and bool(again.collision_free) == bool(
            one.collision_free
        )
        assert again.scene is not None and dataclasses.replace(again, stage="x").ef.shape == one.ef.shape


def test_the_batch_one_entry_plans_as_a_problem_plans(monkeypatch):
    """A batch-1 plan from joint vectors and a scene (the planner's batch-1 entry: no Problem made where
    stage 1 clears it) is the plan of the same Problem (the general path) in every field, to the bit:
    on held-out problems the learned proposals clear and ones they leave to the retreat stage (which
    take the entry's stage 1 along), with float32 tensors and float64 arrays too; where stage 1 clears
    it, or the retreat stage, or (in fixed time) neither, no Problem is made."""
    from kinlearn.data.problem import Problem
    from kinlearn.planning.plan import Plan

    shipped = Planner.default("iiwa14")
    ps = ProblemSet.load(BENCHMARK.with_name("scene_problems_iiwa14.npz"))  # the seven scene families
    stages = set()
    for i in range(0, 140, 7):
        start, goal, scene = ps.problem(i)
        for kw in ({"refine_steps": 0}, {}):
            one = shipped.plan(start, goal, obstacles=scene, **kw)
            ref = shipped.plan(Problem.make(shipped.robot, start, goal, obstacles=scene), **kw)
            stages.add(one.stage)
            assert one.stage == ref.stage
            for f in Plan._BATCHED:
                a, b = getattr(one, f), getattr(ref, f)
                assert a.dtype == b.dtype and torch.equal(a, b), (i, f)
        low = shipped.plan(start.float(), goal.float(), obstacles=scene, refine_steps=0)
        assert low.joints.dtype == torch.float32
        assert torch.equal(
            low.joints,
            shipped.plan(
                start.float().double(), goal.float().double(), obstacles=scene, refine_steps=0
            ).joints.float(),
        )
        arrays = shipped.plan(start.numpy(), goal.numpy(), obstacles=scene, refine_steps=0)
        assert arrays.joints.dtype == torch.float64 and torch.equal(
            arrays.joints, one.joints if one.stage == "learned" else arrays.joints
        )
    assert {"learned", "retreat"} <= stages
    start, goal, _ = ps.problem(0)
    balls = [[0.45, 0.0, 0.55, 0.08], [0.3, 0.3, 0.4, 0.06]]  # spheres (K, 4), read by the entry too
    one = shipped.plan(start, goal, obstacles=balls)
    ref = shipped.plan(Problem.make(shipped.robot, start, goal, obstacles=balls))
    assert one.stage == ref.stage and all(
        torch.equal(getattr(one, f), getattr(ref, f)) for f in Plan._BATCHED if getattr(ref, f) is not None
    )
    with pytest.raises(ObstacleError):
        shipped.plan(start, goal, obstacles=[[0.45, 0.0, 0.55, -0.1]])

    def no_problem(*args, **kwargs):
        raise AssertionError("a Problem was made")

    start, goal, scene = ps.problem(0)
    assert shipped.plan(start, goal, obstacles=scene).stage == "learned"
    fixed = {}  # a problem of each fixed-time verdict, planned in fixed time
    for i in range(140):
        s, g, sc = ps.problem(i)
        fixed.setdefault(shipped.plan(s, g, obstacles=sc, refine_steps=0).stage, (s, g, sc))
        if len(fixed) == 3:
            break
    assert set(fixed) == {"learned", "retreat", "none"}
    for s, g, sc in fixed.values():
        one = shipped.plan(s, g, obstacles=sc, refine_steps=0)
        ref = shipped.plan(Problem.make(shipped.robot, s, g, obstacles=sc), refine_steps=0)
        assert one.stage == ref.stage and all(
            torch.equal(getattr(one, f), getattr(ref, f)) for f in Plan._BATCHED
        )
    monkeypatch.setattr(Problem, "make", no_problem)
    assert shipped.plan(start, goal, obstacles=scene).stage == "learned"
    for stage, (s, g, sc) in fixed.items():  # the entry runs the retreat stage too, and flags a miss
        plan = shipped.plan(s, g, obstacles=sc, refine_steps=0)
        assert plan.stage == stage and bool(plan.collision_free) == (stage != "none")
    s, g, sc = fixed["none"]
    with pytest.raises(
        AssertionError, match="a Problem was made"
    ):  # a later stage asked for: the general path
        shipped.plan(s, g, obstacles=sc, refine_steps=1)


def test_the_batch_one_entry_leaves_bad_input_to_the_checks(planner, problems):
    """Input the batch-1 entry does not take (NaN, joints outside the limits, a state, a batch) is
    checked and explained as every plan's is."""
    from kinlearn.errors import JointLimitError, NonFiniteError

    start, goal, scene = problems.problem(0)
    bad = start.clone()
    bad[1] = float("nan")
    with pytest.raises(NonFiniteError):
        planner.plan(bad, goal, obstacles=scene)
    far = goal.clone()
    far[0] = 10.0
    with pytest.raises(JointLimitError, match="goal"):
        planner.plan(start, far, obstacles=scene)
    with pytest.raises(ShapeError):
        planner.plan(start[:3], goal, obstacles=scene)
    assert planner.plan(start, start, obstacles=scene).joints.eq(start).all()  # no move: the start held
    negative = [[0.45, 0.0, 0.55, -0.1]]  # a ball of negative radius
    with pytest.raises(ObstacleError):
        planner.plan(start, goal, obstacles=negative)
    with pytest.raises(JointLimitError):  # the joints are checked before the scene, as on every path
        planner.plan(start, far, obstacles=negative)
    # input the entry leaves to the general path (a tensor with a gradient, in bfloat16) plans the same
    ref = planner.plan(start, goal, obstacles=scene, refine_steps=0)
    grad = planner.plan(start.clone().requires_grad_(), goal, obstacles=scene, refine_steps=0)
    assert torch.equal(grad.joints, ref.joints) and grad.stage == ref.stage
    half = planner.plan(start.bfloat16(), goal.bfloat16(), obstacles=scene, refine_steps=0)
    assert half.joints.dtype == torch.bfloat16 and half.stage in ("learned", "retreat", "none")


def test_deterministic(planner, problems):
    start, goal, scene = problems.problem(3)
    a = planner.plan(start, goal, obstacles=scene)
    b = planner.plan(start, goal, obstacles=scene)
    assert torch.equal(a.joints, b.joints)


def test_start_in_collision_is_a_failed_plan(planner, robot):
    start = torch.zeros(7, dtype=torch.float64)
    goal = torch.tensor([0.5, 0.3, 0.0, -1.0, 0.0, 0.5, 0.0], dtype=torch.float64)
    ee = kinematics(robot).position(start)
    plan = planner.plan(start, goal, obstacles=torch.cat((ee, torch.tensor([0.05]))).unsqueeze(0))
    assert not bool(plan.collision_free)
    assert not bool(plan.success)
    assert "NO" in plan.summary()


def test_spheres_as_tensors_and_per_plan_scenes(planner, robot):
    g = torch.Generator().manual_seed(1)
    q = robot.sample(6, g, dtype=torch.float64)
    far = torch.tensor([[3.0, 3.0, 3.0, 0.1], [-3.0, 3.0, 3.0, 0.2]])
    one = planner.plan(q[:3], q[3:], obstacles=far)  # one scene for all plans
    per = planner.plan(q[:3], q[3:], obstacles=far.expand(3, 2, 4))  # a scene per plan
    assert torch.equal(one.joints, per.joints)
    assert one.collision_free.shape == (3,)
    empty = planner.plan(q[:3], q[3:], obstacles=torch.zeros(0, 4))
    assert empty.collision_free.shape == (3,)


@pytest.mark.parametrize(
    "obstacles",
    [
        [[0.5, 0.0, 0.5, -0.1]],  # negative radius
        [[0.5, 0.0, 0.5, 0.0]],  # zero radius
        [[0.5, float("nan"), 0.5, 0.1]],  # NaN
        [[0.5, 0.0, 0.5]],  # three numbers
        [0.5, 0.0, 0.5, 0.1],  # no obstacle axis
        "a box",
    ],
)
def test_bad_obstacles_raise(planner, obstacles):
    with pytest.raises(ObstacleError):
        planner.plan(torch.zeros(7), torch.full((7,), 0.3), obstacles=obstacles)


def test_scene_of_another_batch_raises(planner):
    with pytest.raises(ShapeError):
        planner.plan(torch.zeros(2, 7), torch.full((2, 7), 0.3), obstacles=torch.ones(3, 1, 4) * 0.1)


def test_planner_without_obstacle_model_says_so(robot):
    """No obstacle-trained network: a warning, then the straight joint line and bounded refinement,
    checked densely (never a silent plan)."""
    from kinlearn.collision import Scene, body_spheres, check_path
    from kinlearn.errors import NoObstacleModelWarning

    base = Planner.default("iiwa14")
    plain = Planner(robot, base.tm, base.fm, base.im)
    ball = [[0.5, 0.0, 0.5, 0.1]]
    with pytest.warns(NoObstacleModelWarning, match="straight joint line"):
        plan = plain.plan(torch.zeros(7), torch.full((7,), 0.3), obstacles=ball)
    dense = check_path(body_spheres(robot).double(), plan.joints.double(), Scene.from_spheres(ball))
    assert bool(plan.collision_free) == bool(dense.collision_free)


def test_without_obstacles_nothing_changes(planner, robot):
    base = Planner.default("iiwa14")
    q = robot.sample(4, torch.Generator().manual_seed(2), dtype=torch.float64)
    a, b = planner.plan(q[:2], q[2:]), base.plan(q[:2], q[2:])
    assert torch.equal(a.joints, b.joints)
    assert a.collision_free is None


def test_a_scene_with_boxes_and_floor(planner, problems):
    start, goal, scene = problems.problem(5)
    assert isinstance(scene, Scene) and scene.num_boxes > 0 and scene.floor is not None
    plan = planner.plan(start, goal, obstacles=scene)
    assert bool(check_path(planner.body, plan.joints, scene).collision_free) == bool(plan.collision_free)


def test_shipped_planner_plans_around_an_obstacle_and_refines(robot, tmp_path):
    """The shipped obstacle-aware planner: a hard problem (the straight line collides) solved, through
    kinlearn.plan and the CLI, and refinement steps only ever add collision-free plans."""
    import kinlearn
    from kinlearn.cli.main import main

    ps = ProblemSet.load(BENCHMARK)
    hard = torch.nonzero(ps.hard).reshape(-1)[:12]
    sub = ps[hard]
    plain = kinlearn.plan(sub.start, sub.goal, obstacles=sub.scene)
    assert plain.collision_free.float().mean() >= 0.5  # the straight line collides on every one
    refined = kinlearn.plan(sub.start, sub.goal, obstacles=sub.scene, refine_steps=10)
    assert (refined.collision_free | ~plain.collision_free).all()
    # Refinement plans on the proposals' halved segments (the same paths): the free ones are kept, and
    # the shortcut stage shortens them alike (it works on a path's corners, however finely split).
    assert refined.joints.shape == (12, 23, 7)
    for i in torch.nonzero(plain.collision_free).reshape(-1).tolist():
        assert _polyline_gap(refined.joints[i], plain.joints[i]) < 1e-9
        assert _polyline_gap(plain.joints[i], refined.joints[i]) < 1e-9
    check = check_path(Planner.default("iiwa14").body, refined.joints.double(), sub.scene)
    assert torch.equal(refined.collision_free, check.collision_free)
    with pytest.raises(ConfigError):
        kinlearn.plan(sub.start, sub.goal, obstacles=sub.scene, refine_steps=-1)
    i = int(torch.nonzero(plain.collision_free)[0])
    start, goal, scene = sub.problem(i)
    scene.save(tmp_path / "scene.npz")
    fmt = ",".join
    code = main(
        [
            "plan",
            "--start",
            fmt(f"{v:.10f}" for v in start.tolist()),
            "--goal",
            fmt(f"{v:.10f}" for v in goal.tolist()),
            "--obstacles",
            str(tmp_path / "scene.npz"),
        ]
    )
    assert code == 0


def test_readme_ball_example():
    """The README's example: a lone ball across the straight joint line, cleared with refinement."""
    import kinlearn

    start = torch.tensor([-1.2, 0.9, 0.5, -1.6, 0.3, 1.2, -2.0])
    goal = torch.tensor([1.5, -0.4, -0.8, 1.1, -1.9, -0.6, 2.4])
    ball = [[0.58, -0.11, 1.03, 0.12]]
    line = check_path(
        Planner.default("iiwa14").body, torch.stack((start, goal)).double(), Scene(torch.tensor(ball))
    )
    assert not bool(line.collision_free)
    plan = kinlearn.plan(start, goal, obstacles=ball, refine_steps=25)
    assert bool(plan.collision_free) and bool(plan.success)


def test_view_draws_a_plan_among_obstacles(tmp_path, problems):
    pytest.importorskip("matplotlib")
    from kinlearn.cli.main import main

    start, goal, scene = problems.problem(2)
    scene.save(tmp_path / "scene.npz")
    fmt = ",".join
    args = ["view", "--start", fmt(f"{v:.10f}" for v in start.tolist()), "--goal"]
    args += [fmt(f"{v:.10f}" for v in goal.tolist()), "--obstacles", str(tmp_path / "scene.npz")]
    code = main([*args, "--gif", str(tmp_path / "plan.gif")])
    assert code in (0, 1)  # 1: the plan collides (it is shown all the same)
    assert (tmp_path / "plan.gif").stat().st_size > 10_000


def test_a_given_body_is_used_and_left_as_it_is(robot, planner):
    from kinlearn.collision import body_spheres

    body = body_spheres(robot).float()
    mine = Planner(robot, planner.tm, obstacle_tm=planner.obstacle_tm, body=body)
    plan = mine.plan(torch.zeros(7), torch.full((7,), 0.3), obstacles=[[3.0, 3.0, 3.0, 0.1]])
    assert bool(plan.collision_free)
    assert body.radii.dtype == torch.float32  # the planner checks with its own float64 copy
    assert mine.body.radii.dtype == torch.float64 and mine.body is mine.body


def test_scene_reshape_refuses_a_shape_that_does_not_fit(problems):
    scene = problems.scene[:6]
    assert scene.reshape(2, 3).batch_shape == (2, 3)
    with pytest.raises(ObstacleError):
        scene.reshape(4)


def test_refinement_from_a_path_of_the_wrong_shape_raises():
    from kinlearn.planning.obstacle_baselines import trajectory_optimiser

    scene = Scene(torch.tensor([[0.5, 0.0, 0.5, 0.1]], dtype=torch.float64))
    with pytest.raises(ShapeError):
        trajectory_optimiser(torch.zeros(7), torch.full((7,), 0.3), scene, steps=1, init=torch.zeros(5, 6))


@pytest.mark.parametrize("n", [5, 17])  # a few plans and more than SMALL_BATCH (the torch free-space TM)
def test_refined_batches_keep_one_shape_and_agree_with_batch_one(planner, problems, n):
    """Refinement changes some plans of a batch and not others: every plan keeps the batch's one shape
    (2T + 1 configurations), and each is the plan of its problem planned alone. (Without the retreat
    stage, which would clear most of these first.)"""
    planner = Planner(
        planner.robot, planner.tm, planner.fm, planner.im, obstacle_tm=planner.obstacle_tm, retreat=False
    )
    sub = problems[torch.arange(n)]
    batch = planner.plan(sub.start, sub.goal, obstacles=sub.scene, refine_steps=1)
    knots = planner.obstacle_tm.fractions.shape[0] + 2  # T + 1: the proposals' configurations
    assert batch.joints.shape == (n, 2 * knots - 1, 7)
    assert not batch.collision_free.all()  # some plans were refined (or tried), the test means something
    for i in range(0, n, 2):
        start, goal, scene = sub.problem(i)
        alone = planner.plan(start, goal, obstacles=scene, refine_steps=1)
        assert alone.joints.shape == batch.joints.shape[1:]
        assert torch.equal(alone.joints, batch.joints[i])  # made alone in the batch too: bit for bit
        assert bool(alone.collision_free) == bool(batch.collision_free[i])


def test_the_problem_the_other_way_round_adds_its_candidates_walked_backwards(planner, problems):
    """The proposals are the line, the network's C paths for the problem, and its C paths for the problem
    reversed, walked backwards: so planning b → a proposes exactly a → b's paths reversed."""
    import numpy as np

    from kinlearn.collision.kernel import KernelScene
    from kinlearn.data.problem import positions

    start, goal, scene = problems.problem(3)
    q0, q1 = start.double().numpy()[None], goal.double().numpy()[None]
    ef = positions(planner.robot, np.concatenate((q0, q1)))
    ks = KernelScene(scene)
    rows = [(ks.model_rows(), ks.floor)]
    ahead, _ = planner._proposals(q0, ef[:1], q1, ef[1:], rows, 0)
    back, _ = planner._proposals(q1, ef[1:], q0, ef[:1], rows, 0)
    C = planner.obstacle_tm.config.candidates
    assert ahead.shape[1] == 2 * C + 1
    assert np.array_equal(ahead[0, 1 : C + 1], back[0, C + 1 :, ::-1])
    assert np.array_equal(ahead[0, C + 1 :], back[0, 1 : C + 1, ::-1])
    assert not np.allclose(ahead[0, 1 : C + 1], ahead[0, C + 1 :])  # more paths, not the same ones twice


def test_a_free_straight_line_is_the_plan_without_running_the_network(planner, problems):
    """The straight joint line is checked first: it is the shortest candidate, so where it is free it is
    the plan, and the network is not run for that problem (its candidates are copies of the line; a batch
    runs it for the others only); where it collides, the network's candidates are checked as before."""
    import numpy as np

    from kinlearn.data.problem import positions
    from kinlearn.planning.around import _packed_scenes

    free_line = ~problems.hard
    assert bool(free_line.any()) and bool(problems.hard.any())
    i, j = int(free_line.nonzero()[0, 0]), int(problems.hard.nonzero()[0, 0])
    easy = _plan_one(planner, problems, i)
    assert bool(easy.collision_free) and easy.stage == "learned"
    line = np.linspace(0.0, 1.0, np.asarray(easy.joints).shape[0])[:, None]
    s, g, _ = problems.problem(i)
    assert np.allclose(np.asarray(easy.joints), s.numpy() + line * (g - s).numpy(), atol=1e-12)
    both = problems[torch.tensor([i, j])]
    dof = planner.robot.dof
    q0, qT = both.start.double().numpy()[:, :dof], both.goal.double().numpy()[:, :dof]
    e0, eT = positions(planner.robot, q0), positions(planner.robot, qT)
    packed = _packed_scenes(both.scene, 2)
    paths, pick, free = planner._learned(q0, e0, qT, eT, packed, 0)
    assert free[0] and pick[0] == 0 and (paths[0] == paths[0, :1]).all()  # the line, no network
    assert np.array_equal(paths[0, 0], np.asarray(easy.joints))
    rows = [(packed[1].model_rows(), packed[1].floor)]
    every, order = planner._proposals(q0[1:], e0[1:], qT[1:], eT[1:], rows, 0)
    assert np.array_equal(paths[1], every[0])  # the hard one's: the network's candidates
    assert not (paths[1] == paths[1, :1]).all()
    if free[1]:  # the first free one in their order (the line, candidate 0, collides)
        from kinlearn.collision import kernel

        assert pick[1] == kernel.first_free(planner._np_body, every[0], packed[1], order[0][order[0] != 0])


def _plan_one(planner, problems, i):
    s, g, scene = problems.problem(i)
    return planner.plan(s, g, obstacles=scene, refine_steps=0)


def test_the_ur5_plans_with_the_tool_its_benchmarks_carry():
    """The ur5's planner checks with its arm carrying the standard benchmarks' sensor and gripper
    (planning_body): on a held-out problem a gripper-carrying UR5 can start and end in, the plan the arm's
    body alone calls free sweeps the gripper through the scene; the default plan is free for the tool."""
    from kinlearn import load_robot
    from kinlearn.collision import body_spheres, planning_body

    robot = load_robot("ur5")
    planner = Planner.default("ur5")
    assert planner.body.name == "gripper" and planner.body.num_spheres == 40
    assert planning_body(load_robot("panda")).name == body_spheres(load_robot("panda")).name
    tool = planning_body(robot).double()
    problems = ProblemSet.load(BENCHMARK.with_name("scene_problems_ur5_arm.npz"), robot="ur5")
    start, goal, scene = problems.problem(10)
    arm_plan = Planner.default("ur5", body=body_spheres(robot)).plan(
        start, goal, obstacles=scene, refine_steps=0
    )
    assert bool(arm_plan.collision_free)
    assert not bool(check_path(tool, arm_plan.joints, scene).collision_free)  # the gripper collides
    plan = planner.plan(start, goal, obstacles=scene, refine_steps=0)
    assert bool(plan.collision_free) and bool(plan.success)
    assert bool(check_path(tool, plan.joints, scene).collision_free)


def test_a_ur5_plan_between_configurations_within_its_tool_models_limits_stays_within_them():
    """The benchmarks' UR5 (the tool's sphere model) turns ±π where kinlearn's ur5 turns ±2π: a problem
    whose ends lie within ±π is planned within ±π by every stage (the held-out problem 131, whose
    fixed-time plan went to 3.54 rad, and the same problem with the fixed budget of sampling); one whose
    ends leave ±π is planned within the robot's limits."""
    planner = Planner.default("ur5")
    lo, hi = planner.body.limits
    np.testing.assert_allclose(hi, np.pi, atol=1e-7)
    np.testing.assert_allclose(lo, -np.pi, atol=1e-7)
    problems = ProblemSet.load(BENCHMARK.with_name("scene_problems_ur5.npz"), robot="ur5")
    start, goal, scene = problems.problem(131)
    assert float(max(start.abs().max(), goal.abs().max())) <= np.pi
    for kw in ({"refine_steps": 0}, {}):
        plan = planner.plan(start, goal, obstacles=scene, **kw)
        assert bool(plan.success) and plan.stage != "learned"  # the retreat stage's, the sampler's
        assert float(np.abs(np.asarray(plan.joints)).max()) <= np.pi + 1e-9
    start, goal, scene = problems.problem(0)
    assert float(max(start.abs().max(), goal.abs().max())) > np.pi
    plan = planner.plan(start, goal, obstacles=scene, refine_steps=0)
    assert bool(plan.success)
    # one batch holding both: each problem in its own box, the batch-1 verdicts
    both = problems[[131, 0]]
    batch = planner.plan(both.start, both.goal, obstacles=both.scene, refine_steps=0)
    assert bool(batch.success.all())
    assert float(np.abs(np.asarray(batch.joints[0])).max()) <= np.pi + 1e-9


def test_a_panda_problem_beyond_its_limits_but_within_its_benchmark_models_is_planned_within_them():
    """The standard benchmarks' panda (MoveIt's, the spherized file the panda's body comes from) turns every
    joint up to 0.07 rad further than the Franka datasheet limits of kinlearn's panda: a problem among
    obstacles whose goal lies in that band is planned within the model's limits, with a warning, at batch 1
    and in a batch alike, and judged the same by obstacle_outcome; beyond the model's limits, and without
    obstacles (the robot's own planner), it is refused. The ur5 (whose model is narrower) is unchanged."""
    from kinlearn.collision.body import planning_body
    from kinlearn.errors import BeyondLimitsWarning, JointLimitError
    from kinlearn.evaluation.obstacles import obstacle_outcome

    planner = Planner.default("panda")
    robot = planner.robot
    lo, hi = planner.body.outer_limits
    assert np.allclose(hi[[0, 1, 6]], [2.9671, 1.8326, 2.9671]) and hi[3] > 0.08 and (hi >= robot.upper).all()
    start = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])
    goal = np.array([0.3, 0.2, 0.0, -1.6, 0.0, 2.2, 2.93])  # joint 7 beyond 2.8973
    balls = [[0.5, -0.3, 0.9, 0.05]]
    with pytest.warns(BeyondLimitsWarning, match="panda_joint7") as caught:
        one = planner.plan(start, goal, obstacles=balls, refine_steps=0)
    assert caught[0].filename == __file__  # the caller's line
    assert bool(one.success) and bool(one.collision_free)
    joints = np.asarray(one.joints)
    assert (joints >= lo - 1e-9).all() and (joints <= hi + 1e-9).all() and joints[-1, 6] > robot.upper[6]
    with pytest.warns(BeyondLimitsWarning):
        two = planner.plan(np.stack([start, start]), np.stack([goal, goal]), obstacles=balls, refine_steps=0)
    assert bool(two.success.all()) and np.array_equal(np.asarray(two.joints[1]), joints)
    judged = obstacle_outcome(
        planning_body(robot),
        [torch.from_numpy(joints)],
        (start[None], goal[None], Scene(torch.tensor(balls))),
    )
    assert not bool(judged["within_limits"][0]) and not bool(judged["success"][0])  # the robot's own limits
    judged = obstacle_outcome(
        planning_body(robot), [torch.from_numpy(joints)], (start[None], goal[None], Scene(torch.tensor(balls))),
        limits=(lo, hi),
    )  # fmt: skip
    assert bool(judged["success"][0])
    with pytest.raises(JointLimitError, match=r"2\.9671"):
        planner.plan(start, np.where(np.arange(7) == 6, 3.0, goal), obstacles=balls)
    with pytest.raises(JointLimitError, match=r"2\.8973"):
        planner.plan(start, goal)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # within the robot's own limits: no warning
        assert bool(planner.plan(start, np.where(np.arange(7) == 6, 2.8, goal), obstacles=balls).success)
    ur5 = Planner.default("ur5")
    assert ur5._obstacle_robot is ur5.robot


def test_the_plan_command_takes_a_sphere_set(tmp_path, capsys):
    """``kinlearn plan --sphere-set``: the ur5's arm alone calls problem 10's plan free, its default body
    (with the gripper) plans around it; an unknown set, or a set without obstacles, is refused."""
    from kinlearn.cli.main import main

    problems = ProblemSet.load(BENCHMARK.with_name("scene_problems_ur5_arm.npz"), robot="ur5")
    start, goal, scene = problems.problem(10)
    scene.save(tmp_path / "scene.npz")
    joints = [",".join(f"{v:.17g}" for v in q.tolist()) for q in (start, goal)]
    args = [
        "plan",
        "--robot",
        "ur5",
        "--start",
        joints[0],
        "--goal",
        joints[1],
        "--refine-steps",
        "0",
        "--joints",
    ]
    obstacles = ["--obstacles", str(tmp_path / "scene.npz")]
    assert main([*args, *obstacles]) == 0
    with_tool = capsys.readouterr().out
    assert main([*args, *obstacles, "--sphere-set", "spherized"]) == 0
    arm_alone = capsys.readouterr().out
    assert "retreat" in with_tool and with_tool != arm_alone  # the tool takes another path
    assert main([*args, *obstacles, "--sphere-set", "hand"]) == 2
    assert "no 'hand' sphere set" in capsys.readouterr().err
    assert main([*args, "--sphere-set", "spherized"]) == 2
    assert "--sphere-set" in capsys.readouterr().err


def test_a_plan_whose_end_collides_says_why():
    """A plan no stage can make collision-free because its start or goal collides before any motion comes
    back flagged with a CollidingEndWarning naming the problem; where the scene overlaps the fixed base (a
    floor given as a box), the warning says so and what to do. Plans whose ends are free warn nothing."""
    from kinlearn.collision.geometry import Box
    from kinlearn.errors import CollidingEndWarning

    planner = Planner.default("iiwa14")
    start = torch.tensor([-1.2, 0.9, 0.5, -1.6, 0.3, 1.2, -2.0], dtype=torch.float64)
    goal = torch.tensor([1.5, -0.4, -0.8, 1.1, -1.9, -0.6, 2.4], dtype=torch.float64)
    hand = kinematics(planner.robot, "fast").position(start)
    slab = Box((0.0, 0.0, -0.5), (3.0, 3.0, 0.5), np.eye(3))  # the floor as a box: the base's spheres in it
    ball = [*hand.tolist(), 0.05]  # a ball at the start's hand
    for obstacles, base in ((Scene.from_primitives([slab]), True), (Scene.from_spheres([ball]), False)):
        for kwargs in ({"refine_steps": 0}, {"deadline": 0.02}):
            with pytest.warns(CollidingEndWarning, match="start of problem") as record:
                plan = planner.plan(start, goal, obstacles=obstacles, **kwargs)
            assert not bool(plan.collision_free) and not bool(plan.success)
            assert ("fixed base" in str(record[0].message)) == base
    with pytest.warns(CollidingEndWarning, match=r"problem\(s\) 0, 1"):  # a batch names each problem
        planner.plan(
            torch.stack((start, start)), torch.stack((goal, goal)), obstacles=Scene.from_primitives([slab])
        )
    with warnings.catch_warnings():
        warnings.simplefilter("error", CollidingEndWarning)
        far = Scene.from_spheres([[2.0, 2.0, 2.0, 0.1]])
        assert bool(planner.plan(start, goal, obstacles=far, refine_steps=0).collision_free)


def _polyline_gap(points: torch.Tensor, polyline: torch.Tensor) -> float:
    """The largest distance (rad) from a knot of ``points`` to the polyline ``polyline``."""
    a, b = polyline[:-1].double().numpy(), polyline[1:].double().numpy()
    d = b - a
    worst = 0.0
    for p in points.double().numpy():
        t = np.clip(((p - a) * d).sum(-1) / np.maximum((d * d).sum(-1), 1e-300), 0.0, 1.0)
        worst = max(worst, float(np.linalg.norm(a + t[:, None] * d - p, axis=-1).min()))
    return worst
