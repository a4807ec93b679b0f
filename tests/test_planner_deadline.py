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
    return Planner.default("panda")


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
