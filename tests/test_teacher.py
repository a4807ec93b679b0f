"""A planner as a teacher (:mod:`kinlearn.planning.teacher`): its own plans as the targets of
self-distillation, and a training that reads them."""

from __future__ import annotations

import json

import pytest
import torch

from kinlearn import load_robot
from kinlearn.data.problems import ProblemConfig, make_problems
from kinlearn.data.target_paths import read_target_paths, target_paths_file
from kinlearn.errors import ConfigError
from kinlearn.models.obstacle_path import load_obstacle_model
from kinlearn.planning.planner import DEFAULT_CHECKPOINTS, Planner
from kinlearn.planning.teacher import planner_paths
from kinlearn.training.obstacle_path import ObstacleLossConfig, ObstacleTrainConfig, train_obstacle_model


@pytest.fixture(scope="module")
def problems(tmp_path_factory):
    """Four unverified cubby problems of the iiwa14 (starts and goals in cells)."""
    pset = make_problems("cubby", 4, 4343, config=ProblemConfig(verify=False))
    path = tmp_path_factory.mktemp("teacher") / "cubby.npz"
    pset.save(path)
    return path, pset


def test_the_planners_own_plans_are_written_beside_the_set(problems):
    path, pset = problems
    folder = DEFAULT_CHECKPOINTS / "iiwa14"
    out = planner_paths(folder, path, 6)
    assert out == target_paths_file(path, "planner", 6)
    from kinlearn.training.obstacle_path import planner_paths as read

    paths, found = read(path, load_robot("iiwa14"), 6)
    assert paths.shape == (4, 7, 7) and found.dtype == torch.bool
    planner = Planner.load(folder, body=pset.body(load_robot("iiwa14")).double())
    for i in range(4):  # each found path is the plan itself, resampled: from the start to the goal
        s, g, sc = pset.problem(i)
        plan = planner.plan(s, g, obstacles=sc)
        assert bool(found[i]) == bool(plan.success)
        if found[i]:
            assert torch.allclose(paths[i, 0], s.double()) and torch.allclose(paths[i, -1], g.double())
        else:
            assert not paths[i].any()
    assert int(found.sum()) >= 2
    stamp = out.stat().st_mtime_ns
    assert planner_paths(folder, path, 6) == out and out.stat().st_mtime_ns == stamp  # kept, not made again


def test_a_teacher_of_fixed_time_stages_shows_no_searched_path(problems, tmp_path):
    path, pset = problems
    own = tmp_path / path.name  # a copy of the set: its teacher file is this test's own
    own.write_bytes(path.read_bytes())
    folder = DEFAULT_CHECKPOINTS / "iiwa14"
    with pytest.raises(ConfigError, match="stages must be one of"):
        planner_paths(folder, own, 6, stages="sampler")
    from kinlearn.training.obstacle_path import planner_paths as read

    planner_paths(folder, own, 6)
    _, found_default = read(own, load_robot("iiwa14"), 6)
    planner_paths(folder, own, 6, stages="fixed")  # other stages: the file is made again
    assert read_target_paths(own, "iiwa14", "planner", 6, 4)[0]["plan"] == "fixed"
    paths, found = read(own, load_robot("iiwa14"), 6)
    planner = Planner.load(folder, body=pset.body(load_robot("iiwa14")).double())
    for i in range(4):  # the fixed-time plans alone: what plan(..., refine_steps=0) clears, no more
        s, g, sc = pset.problem(i)
        plan = planner.plan(s, g, obstacles=sc, refine_steps=0)
        assert bool(found[i]) == bool(plan.success)
        assert plan.stage in ("learned", "retreat", "none")
        if found[i]:
            assert torch.allclose(paths[i, 0], s.double()) and torch.allclose(paths[i, -1], g.double())
    assert bool((found <= found_default).all())


def test_a_training_taught_by_a_planner_reads_its_plans_and_says_so(problems, tmp_path):
    path, _ = problems
    base = dict(
        problems=(str(path),),
        iterations=40,
        batch_size=4,
        checkpoint_every=20,
        lr=3e-3,
        model={"hidden": [32, 32], "encoder": [16, 16], "candidates": 3, "modes": 3},
        teacher="planner",
        solvable_only=True,
    )
    with pytest.raises(ConfigError, match="teacher must be"):
        ObstacleTrainConfig(**{**base, "teacher": "oracle"})
    cfg = ObstacleTrainConfig(**base, loss=ObstacleLossConfig(imitation=500.0))
    with pytest.raises(ConfigError, match="planner's paths"):  # at 11 knots: none were made
        train_obstacle_model(
            ObstacleTrainConfig(**{**base, "model": {**base["model"], "steps": 11}}), tmp_path / "x"
        )
    planner_paths(DEFAULT_CHECKPOINTS / "iiwa14", path, cfg.model_config(load_robot("iiwa14")).steps)
    tm = train_obstacle_model(cfg, tmp_path / "run", progress=False)
    assert tm.distilled == "planner" == load_obstacle_model(tmp_path / "run" / "tm_obstacles.pt").distilled
    logs = [json.loads(x) for x in (tmp_path / "run" / "metrics.jsonl").read_text().splitlines()]
    imit = [x["train/imitation"] for x in logs if "train/imitation" in x]
    assert len(imit) == 2 and imit[-1] < imit[0]
    assert cfg.to_dict()["teacher"] == "planner"
    assert "teacher" not in ObstacleTrainConfig(**{**base, "teacher": "sampler"}).to_dict()
    assert ObstacleTrainConfig.from_dict(cfg.to_dict()) == cfg
