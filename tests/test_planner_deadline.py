"""The obstacle plan's stages under a deadline: plan.stage says which stage made each plan, the sampling
stage clears what the learned proposals did not, a plan it makes is free by the dense check of its own
joints, and the deadline's clock cuts the sampling stage off (a fake clock, no wall time)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from kinlearn.collision import check_path
from kinlearn.data.problems import ProblemSet
from kinlearn.errors import ConfigError, NoObstacleModelWarning
from kinlearn.planning import stages
from kinlearn.planning.planner import Planner

SCENES = Path(__file__).resolve().parents[1] / "benchmarks" / "data" / "scene_problems_panda.npz"


@pytest.fixture(scope="module")
def panda():
    """The panda's planner without an obstacle network or the retreat stage: its learned stage is the
    straight joint line alone, so the hard problems below are left to the later stages."""
    base = Planner.default("panda")
    return Planner(base.robot, base.tm, base.fm, base.im, retreat=False)


@pytest.fixture(scope="module")
def hard(panda):
    """Held-out panda problems of the scene families whose straight joint line collides."""
    ps = ProblemSet.load(SCENES, robot="panda")
    return ps[ps.hard][:: max(1, int(ps.hard.sum()) // 6)][:6]


def _plan(planner, *args, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NoObstacleModelWarning)
        return planner.plan(*args, **kw)


def test_stages_without_and_with_a_deadline(panda, hard):
    start, goal, scene = hard.problem(0)
    free_space = _plan(panda, start, goal)
    assert free_space.stage == "learned"
    fixed = _plan(panda, start, goal, obstacles=scene, refine_steps=0)
    assert fixed.stage == "none" and not bool(fixed.collision_free) and not bool(fixed.success)
    again = _plan(panda, start, goal, obstacles=scene, refine_steps=0)
    assert torch.equal(again.joints, fixed.joints)  # no deadline: deterministic
    solved = 0
    for i in range(len(hard)):
        start, goal, scene = hard.problem(i)
        # A generous deadline: the sampling stage returns as soon as it has a path.
        plan = _plan(panda, start, goal, obstacles=scene, deadline=30.0)
        assert plan.stage in stages.STAGES
        if plan.stage == "rrt":
            solved += 1
            assert bool(plan.collision_free) and bool(plan.success)
            # free by the torch dense check of the plan's own joints (an independent implementation)
            assert bool(check_path(panda.body, plan.joints, scene).collision_free)
            assert torch.equal(plan.joints[0], start.to(plan.joints.dtype))
            assert torch.equal(plan.joints[-1], goal.to(plan.joints.dtype))
        else:
            assert plan.stage == "learned" or not bool(plan.success)
    assert solved >= len(hard) - 1


def test_a_batch_has_a_stage_per_plan(panda, hard):
    sub = hard[:2]
    plan = _plan(panda, sub.start, sub.goal, obstacles=sub.scene, deadline=30.0)
    assert isinstance(plan.stage, np.ndarray) and plan.stage.shape == (2,)
    assert plan[1].stage == str(plan.stage[1]) and set(plan.stage) <= set(stages.STAGES)
    assert bool(plan.collision_free.all()) == all(s != "none" for s in plan.stage)


class _SlowClock:
    """Every reading is ``step`` seconds after the one before: any work takes that long."""

    def __init__(self, step: float):
        self.now, self.step, self.reads = 0.0, step, 0

    def __call__(self) -> float:
        self.now += self.step
        self.reads += 1
        return self.now


def test_the_deadline_cuts_the_sampling_stage_off(panda, hard, monkeypatch):
    start, goal, scene = hard.problem(0)
    clock = _SlowClock(0.02)  # 20 ms a reading: a deadline of 50 ms leaves one round of sampling
    monkeypatch.setattr(stages.time, "perf_counter", clock)
    plan = _plan(panda, start, goal, obstacles=scene, deadline=0.05)
    assert plan.stage == "none" and not bool(plan.success)  # one RRT round cannot solve it
    assert clock.reads <= 8  # the deadline was looked at and the stage stopped
    with pytest.raises(ConfigError, match="deadline"):
        _plan(panda, start, goal, obstacles=scene, deadline=-1.0)


def test_the_retreat_stage_leaves_the_sampler_the_rest_of_a_deadline(hard, monkeypatch):
    """The retreat stage starts work only within the planner's share of a deadline (``retreat_share``),
    so that a slow retreat cannot spend the time the sampling stage needs; without a deadline it always
    runs. The arm's default share is the measured one; a bad share is refused."""
    base = Planner.default("panda")
    calls = []

    def planner_with(share):
        planner = Planner(base.robot, base.tm, base.fm, base.im, retreat_share=share)  # line, then retreat
        inner = planner._retreat

        def counted(*args, **kw):
            calls.append(1)
            return inner(*args, **kw)

        monkeypatch.setattr(planner, "_retreat", counted)
        return planner

    start, goal, scene = hard.problem(0)
    _plan(planner_with(0.0), start, goal, obstacles=scene, refine_steps=0)
    assert len(calls) == 1  # fixed time: the stage runs, whatever the share
    _plan(planner_with(1.0), start, goal, obstacles=scene, deadline=30.0)
    assert len(calls) == 2  # a deadline with its share left: it runs
    plan = _plan(planner_with(0.0), start, goal, obstacles=scene, deadline=30.0)
    assert len(calls) == 2 and plan.stage in ("rrt", "none")  # its share spent: the sampler goes next
    assert base.retreat_share == stages.RETREAT_SHARE == stages.retreat_share("panda")
    assert Planner(base.robot, base.tm).retreat_share == stages.RETREAT_SHARE
    assert stages.retreat_share("ur5") == 0.0
    for bad in (-0.1, 1.5, float("nan"), True, "0.3"):
        with pytest.raises(ConfigError, match="retreat_share"):
            Planner(base.robot, base.tm, retreat_share=bad)


def test_plan_command_takes_a_deadline(hard, tmp_path, capsys):
    import yaml

    from kinlearn.cli.main import main
    from kinlearn.collision import Scene
    from kinlearn.collision.geometry import Plane

    start, goal, scene = hard.problem(0)
    # The obstacles without the floor (MoveIt has no floor: written as a box, it would hold the base).
    objects = Scene.from_primitives([p for p in scene.primitives() if not isinstance(p, Plane)])
    (tmp_path / "scene.yaml").write_text(yaml.safe_dump(objects.to_moveit(frame_id="panda_link0")))
    joints = [",".join(f"{v:.17g}" for v in q.tolist()) for q in (start, goal)]
    args = ["plan", "--robot", "panda", "--scene", str(tmp_path / "scene.yaml"), "--start", joints[0]]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NoObstacleModelWarning)
        assert main([*args, "--goal", joints[1], "--deadline", "30"]) == 0
        out = capsys.readouterr().out
        assert "stage" in out and "rrt" in out
        assert (
            main([*args, "--goal", joints[1], "--refine-steps", "0"]) == 1
        )  # the line alone does not clear it
        assert "none" in capsys.readouterr().out
    no_scene = ["plan", "--robot", "panda", "--start", joints[0], "--goal", joints[1], "--deadline", "1"]
    assert main(no_scene) == 2
    assert "--deadline bounds planning around obstacles" in capsys.readouterr().err
    with pytest.raises(SystemExit) as refused:  # refused as the options are parsed
        main([*args, "--goal", joints[1], "--deadline", "0"])
    assert refused.value.code == 2


def test_an_arm_without_an_obstacle_network_samples_by_a_budget_of_iterations(panda, hard):
    """No deadline, no refine_steps: the panda (no obstacle network) samples for a fixed number of
    iterations after its straight line, the same plan every call (a budget of work, not of time)."""
    from kinlearn.planning.planner import DEFAULT_RRT_ITERATIONS

    assert DEFAULT_RRT_ITERATIONS > 0
    start, goal, scene = hard.problem(1)
    with pytest.warns(NoObstacleModelWarning, match="iterations"):
        a = panda.plan(start, goal, obstacles=scene)
    b = _plan(panda, start, goal, obstacles=scene)
    assert a.stage == b.stage == "rrt" and bool(a.success)
    assert torch.equal(a.joints, b.joints)
    assert bool(check_path(panda.body, a.joints, scene).collision_free)
    line = _plan(panda, start, goal, obstacles=scene, refine_steps=0)  # asked for: no sampling
    assert line.stage == "none"


def test_an_arm_with_an_obstacle_network_samples_what_its_proposals_left():
    """By default (no deadline, no refine_steps) a plan the network's proposals did not clear gets the
    same budget of RRT-Connect iterations, with no warning and the same plan every call; refine_steps=0
    asks for the fixed-time proposals alone."""
    from kinlearn.planning.planner import DEFAULT_RRT_ITERATIONS

    assert DEFAULT_RRT_ITERATIONS > 0
    iiwa = Planner.default("iiwa14")
    assert iiwa.obstacle_tm is not None
    ps = ProblemSet.load(SCENES.with_name("scene_problems_iiwa14.npz"), robot="iiwa14")
    hard = ps[ps.hard]
    for i in range(len(hard)):
        start, goal, scene = hard.problem(i)
        fixed = iiwa.plan(start, goal, obstacles=scene, refine_steps=0)
        if fixed.stage == "none":
            break
    else:
        pytest.fail("the network cleared every hard problem: pick a harder set for this test")
    assert not bool(fixed.collision_free)
    with warnings.catch_warnings():
        warnings.simplefilter("error", NoObstacleModelWarning)
        a = iiwa.plan(start, goal, obstacles=scene)
    b = iiwa.plan(start, goal, obstacles=scene)
    assert a.stage == "rrt" and bool(a.success) and torch.equal(a.joints, b.joints)
    assert bool(check_path(iiwa.body, a.joints, scene).collision_free)


def test_the_kernels_are_loaded_before_the_first_deadline_starts():
    """A first plan among obstacles in a fresh process loads the compiled check and sampler and the
    planner's sphere body before its deadline's clock starts (a deadline of 50 ms is no use if loading
    them takes a second of it): when the Deadline is made, the kernels hold compiled code and the body
    is packed. A planner without obstacles loads nothing."""
    import subprocess
    import sys

    code = """
import torch
from kinlearn.planning import planner as P, stages
from kinlearn.collision import kernel, rrt
seen = []
class Spy(stages.Deadline):
    def __init__(self, *a, **k):
        pl = PL[0]
        seen.append((bool(kernel.first_free_boxed.signatures), bool(rrt._grow.signatures),
                     pl._np_body_cache is not None))
        super().__init__(*a, **k)
P.Deadline = Spy
PL = [P.Planner.default("panda")]
q = torch.as_tensor((PL[0]._lo_np + PL[0]._hi_np) / 2)
PL[0].plan(q, q + 0.05)
first = [(bool(kernel.first_free_boxed.signatures), bool(rrt._grow.signatures), PL[0]._np_body_cache is not None)]
PL[0].plan(q, q + 0.05, obstacles=[[0.6, 0.0, 0.9, 0.05]], deadline=0.05)
print(first[0], seen[-1])
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split("\n")[-2] == "(False, False, False) (True, True, True)"


_COMPILED_AFTER_WARM_UP = """
import sys, warnings, numba
import kinlearn
from kinlearn.data.problems import ProblemSet

def compiled():
    return {
        f"{m.__name__}.{k}": len(v.signatures)
        for m in list(sys.modules.values()) if getattr(m, "__name__", "").startswith("kinlearn")
        for k, v in vars(m).items() if isinstance(v, numba.core.registry.CPUDispatcher)
    }

warnings.simplefilter("ignore")
planner = kinlearn.Planner.default("panda")
planner.warm_up()
before = compiled()
ps = ProblemSet.load(sys.argv[1], robot="panda")
for i in (1, 4, 33, 60):  # retreats, a join, transfers, open directions, a network plan
    start, goal, scene = ps.problem(i)
    planner.plan(start, goal, obstacles=scene, refine_steps=0)
    planner.plan(start, goal, obstacles=scene, deadline=0.05)
print(sorted(k for k, n in compiled().items() if n != before.get(k, 0)))
"""


def test_no_plan_compiles_after_the_warm_up():
    """Planner.warm_up (which plan calls before a deadline's clock starts) loads every compiled function
    the stages call: the plans after it compile nothing (in a fresh process, where nothing else has)."""
    import subprocess
    import sys

    out = subprocess.run(
        [sys.executable, "-c", _COMPILED_AFTER_WARM_UP, str(SCENES)],
        capture_output=True,
        text=True,
        timeout=600,
        check=True,
    )
    assert out.stdout.strip().splitlines()[-1] == "[]", out.stdout + out.stderr
