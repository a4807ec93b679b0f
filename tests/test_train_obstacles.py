"""Self-supervised training of the obstacle-aware TM: its loss, its clearance, learning, resuming."""

from __future__ import annotations

import json

import pytest
import torch

from kinlearn import load_robot
from kinlearn.collision import body_obstacle_distance, body_spheres
from kinlearn.data.problems import ProblemConfig, make_problems
from kinlearn.errors import CheckpointError, ConfigError
from kinlearn.io import load_checkpoint
from kinlearn.models.obstacle_path import ObstaclePathConfig, ObstaclePathModel, load_obstacle_model
from kinlearn.training.obstacle_path import (
    ObstacleLossConfig,
    ObstacleTrainConfig,
    _scene_clearance,
    candidate_losses,
    train_obstacle_model,
)


@pytest.fixture(scope="module")
def problems(tmp_path_factory):
    """Six unverified problems (two per family) in one file."""
    from kinlearn.data.problems import ProblemSet

    cfg = ProblemConfig(verify=False)
    sets = [make_problems(f, 2, 4242, config=cfg) for f in ("tabletop", "shelf", "barrier")]
    path = tmp_path_factory.mktemp("problems") / "train.npz"
    ProblemSet.concat(sets).save(path)
    return path, ProblemSet.concat(sets)


def _tiny(problems, **fields) -> ObstacleTrainConfig:
    base = dict(
        problems=(str(problems[0]),),
        iterations=12,
        batch_size=6,
        checkpoint_every=4,
        lr=3e-3,
        model={"hidden": [32, 32], "encoder": [16, 16], "candidates": 3, "modes": 3},
    )
    base.update(fields)
    return ObstacleTrainConfig(**base)


def test_lean_clearance_matches_the_library(problems):
    _, ps = problems
    body = body_spheres(load_robot("iiwa14")).double()
    q = torch.stack((ps.start, ps.goal), dim=1)  # (N, 2, dof)
    centres = body(q)
    mine = _scene_clearance(centres, body.radii, ps.scene, body.floor_mask)
    _, ref = body_obstacle_distance(
        centres.transpose(0, 1), body.radii, ps.scene, per_sphere=True, floor_mask=body.floor_mask
    )
    assert torch.allclose(mine, ref.transpose(0, 1), atol=1e-9)


def test_collision_term_sees_a_colliding_candidate(problems):
    _, ps = problems
    robot = load_robot("iiwa14")
    body = body_spheres(robot).float()
    tm = ObstaclePathModel(ObstaclePathConfig.for_robot(robot, hidden=(16,), encoder=(8,), candidates=2))
    from kinlearn.body.kinematics import kinematics

    kin = kinematics(robot)
    s0 = torch.cat((ps.start, kin.position(ps.start)), -1).float()
    sT = torch.cat((ps.goal, kin.position(ps.goal)), -1).float()
    scene = ps.scene.to(dtype=torch.float32)
    per, terms = candidate_losses(tm, body, s0, sT, scene, ObstacleLossConfig(), torch.tensor([0.0, 0.5]))
    assert per.shape == (len(ps), 2)
    # A hard problem's straight line collides; the untrained candidates stay near it and pay for that.
    hard = ps.hard
    assert hard.any()
    assert (terms["collision"][hard] > 0).any()
    assert torch.isfinite(per).all()


def test_training_lowers_the_loss_and_resumes_bit_identically(problems, tmp_path, monkeypatch):
    cfg = _tiny(problems)
    full = train_obstacle_model(cfg, tmp_path / "full", progress=False)
    records = [json.loads(line) for line in (tmp_path / "full" / "metrics.jsonl").read_text().splitlines()]
    assert records[-1]["train/loss"] < records[0]["train/loss"]
    # The families it saw are recorded in the model and its checkpoint.
    assert full.families == ("tabletop", "shelf", "barrier")
    assert load_obstacle_model(tmp_path / "full" / "tm_obstacles.pt").families == full.families
    assert full.body == body_spheres(load_robot("iiwa14")).name  # and the body it learned through
    assert load_obstacle_model(tmp_path / "full" / "tm_obstacles.pt").body == full.body
    # The same run, killed in its ninth iteration (after the checkpoint at 8), then resumed.
    import kinlearn.training.obstacle_path as mod

    real, calls = mod.candidate_losses, {"n": 0}

    def failing(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 9:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(mod, "candidate_losses", failing)
    with pytest.raises(KeyboardInterrupt):
        train_obstacle_model(cfg, tmp_path / "part", progress=False)
    monkeypatch.setattr(mod, "candidate_losses", real)
    extra = load_checkpoint(tmp_path / "part" / "tm_obstacles.pt", kind=ObstaclePathModel.kind)["extra"]
    assert (extra["step"], extra["unit"]) == (8, "iteration")
    resumed = train_obstacle_model(cfg, tmp_path / "part", progress=False)
    for a, b in zip(full.state_dict().values(), resumed.state_dict().values(), strict=True):
        assert torch.equal(a, b)


def test_resume_refuses_another_configuration(problems, tmp_path):
    train_obstacle_model(_tiny(problems, iterations=4), tmp_path, progress=False)
    with pytest.raises(CheckpointError):
        train_obstacle_model(_tiny(problems, iterations=4, lr=1e-3), tmp_path, progress=False)


def test_bad_configs(problems):
    with pytest.raises(ConfigError):
        ObstacleTrainConfig()  # no problems
    with pytest.raises(ConfigError):
        _tiny(problems, body="learned")  # without a checkpoint
    with pytest.raises(ConfigError):
        _tiny(problems, points=0)
    with pytest.raises(ConfigError):
        ObstacleLossConfig(margin=-0.01)


def test_fine_tuning_starts_from_the_given_weights(problems, tmp_path):
    first = train_obstacle_model(_tiny(problems, iterations=4), tmp_path / "a", progress=False)
    cfg = _tiny(problems, iterations=1, lr=1e-9, init_checkpoint=str(tmp_path / "a" / "tm_obstacles.pt"))
    tuned = train_obstacle_model(cfg, tmp_path / "b", progress=False)
    for a, b in zip(first.state_dict().values(), tuned.state_dict().values(), strict=True):
        assert torch.allclose(a, b, atol=1e-6)
    other = _tiny(
        problems,
        iterations=1,
        init_checkpoint=str(tmp_path / "a" / "tm_obstacles.pt"),
        model={"hidden": [16], "encoder": [8], "candidates": 3, "modes": 3},
    )
    with pytest.raises(ConfigError, match="architecture"):
        train_obstacle_model(other, tmp_path / "c", progress=False)


def test_train_obstacle_planner_command(tmp_path):
    """The command generates its problems (of the families chosen, less the one left out), trains,
    records its run and copies the model, with the families it saw, into a planner."""
    import shutil

    from kinlearn.cli.main import main
    from kinlearn.planning.planner import DEFAULT_CHECKPOINTS, Planner

    planner_dir = tmp_path / "planner"
    shutil.copytree(DEFAULT_CHECKPOINTS / "iiwa14", planner_dir)
    (planner_dir / "tm_obstacles.pt").unlink()
    run = tmp_path / "run"
    args = ["train-obstacle-planner", "--problems-per-family", "1", "--iterations", "2", "--batch-size", "3"]
    args += ["--families", "legacy", "--leave-out", "barrier"]
    code = main(
        [*args, "--candidates", "2", "--run-dir", str(run), "--planner", str(planner_dir), "--no-progress"]
    )
    assert code == 0
    assert (run / "tm_obstacles.pt").is_file() and (run / "config.json").is_file()
    assert sorted(p.name for p in (run / "problems").glob("*.npz")) == ["shelf_00_1.npz", "tabletop_00_1.npz"]
    assert json.loads((run / "config.json").read_text())["obstacle_planner"]["families"] == [
        "tabletop",
        "shelf",
    ]
    planner = Planner.load(planner_dir)
    assert planner.obstacle_tm is not None and planner.obstacle_tm.config.candidates == 2
    assert planner.obstacle_tm.families == ("tabletop", "shelf")  # barrier left out, and it says so
    # The same run directory is refused without --resume or --overwrite.
    assert main([*args, "--run-dir", str(run), "--no-progress"]) == 2
    # An unknown sphere set is refused before anything is written.
    assert main([*args, "--run-dir", str(tmp_path / "other"), "--sphere-set", "hand", "--no-progress"]) == 2
    assert not (tmp_path / "other").exists()


def test_train_obstacle_planner_taught_by_the_shipped_planner(tmp_path):
    """--teacher planner: the shipped planner plans the training problems first (its plans written beside
    them), the network is distilled from them and says so, and the run records its teacher (and its stages,
    --teacher-stages fixed); naming a teacher planner or its stages without --teacher planner is refused
    before anything is written."""
    from kinlearn.cli.main import main
    from kinlearn.models.obstacle_path import load_obstacle_model

    run = tmp_path / "run"
    args = [
        "train-obstacle-planner",
        "--families",
        "cubby",
        "--problems-per-family",
        "2",
        "--iterations",
        "2",
    ]
    args += ["--batch-size", "2", "--candidates", "2", "--no-progress"]
    taught = ["--teacher", "planner", "--imitation", "300", "--solvable-only"]
    assert main([*args, *taught, "--run-dir", str(run)]) == 0
    assert [p.name for p in (run / "problems").glob("*.planner11.npz")] == ["cubby_00_2.planner11.npz"]
    assert load_obstacle_model(run / "tm_obstacles.pt").distilled == "planner"
    record = json.loads((run / "config.json").read_text())["obstacle_planner"]
    assert record["teacher"]["planner"].endswith("iiwa14") and record["imitation"] == 300
    other = tmp_path / "other"
    assert main([*args, "--teacher-planner", str(run), "--run-dir", str(other)]) == 2
    assert main([*args, "--teacher-stages", "fixed", "--run-dir", str(other)]) == 2
    assert not other.exists()
    fixed = tmp_path / "fixed"  # taught by the fixed-time stages alone: recorded with the teacher
    assert main([*args, *taught, "--teacher-stages", "fixed", "--run-dir", str(fixed)]) == 0
    record = json.loads((fixed / "config.json").read_text())["obstacle_planner"]
    assert record["teacher"]["stages"] == "fixed"


def test_train_obstacle_planner_refuses_a_planner_folder_without_a_planner(tmp_path, capsys):
    from kinlearn.cli.main import main

    args = ["train-obstacle-planner", "--problems-per-family", "1", "--iterations", "1"]
    code = main([*args, "--run-dir", str(tmp_path / "run"), "--planner", str(tmp_path), "--no-progress"])
    assert code == 2
    assert "no tm.pt" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()  # refused before anything was written


def test_training_problems_of_the_named_families_only(tmp_path):
    """make_training_problems writes the families asked for (default: the three the shipped network
    learned from), with their training seeds, and refuses a family that does not exist."""
    from kinlearn.data.problems import LEGACY_FAMILIES, ProblemSet
    from kinlearn.training.obstacle_path import TRAINING_SEEDS, make_training_problems

    assert [TRAINING_SEEDS[f] for f in LEGACY_FAMILIES] == [2001, 2002, 2003]
    paths = make_training_problems(tmp_path, 1, families=("cage",))
    assert [p.name for p in paths] == ["cage_00_1.npz"]
    made = ProblemSet.load(paths[0])
    assert len(made.of("cage")) == 1 and int(made.seed[0]) != 0
    for bad in ((), ("kitchen",)):
        with pytest.raises(ConfigError, match="training families"):
            make_training_problems(tmp_path, 1, families=bad)


def test_training_problems_and_the_trained_body_follow_the_sphere_set(tmp_path):
    """The ur5's training problems are made for its planning body (the arm with its gripper) unless a
    set is named; the analytic body training goes through is the one its problems were made for, and a
    folder of problems made for another body is refused rather than mixed."""
    from kinlearn.data.problems import ProblemSet
    from kinlearn.training.obstacle_path import ObstacleTrainConfig, build_body, make_training_problems

    ur5 = load_robot("ur5")
    tool = make_training_problems(tmp_path / "tool", 1, robot=ur5, families=("wall",))
    pool = ProblemSet.load(tool[0], robot="ur5")
    assert pool.body_name == "gripper"
    cfg = ObstacleTrainConfig(robot="ur5", problems=tuple(map(str, tool)))
    assert build_body(cfg, ur5, pool).num_spheres == pool.body(ur5).num_spheres == 40
    arm = make_training_problems(tmp_path / "arm", 1, robot=ur5, families=("wall",), sphere_set="spherized")
    assert build_body(cfg, ur5, ProblemSet.load(arm[0], robot="ur5")).num_spheres == 23
    with pytest.raises(ConfigError, match="made for the 'gripper' body"):
        make_training_problems(tmp_path / "tool", 1, robot=ur5, families=("wall",), sphere_set="spherized")


def test_training_problems_within_the_bodys_limits_train_and_search_in_that_box(tmp_path):
    """--within body: the ur5's training problems start and end within its tool model's ±π, the set
    says so, a folder made within other limits is refused, the offline sampler's paths stay in that
    box and the loss clamps knots to it and charges a knot beyond it."""
    import numpy as np

    from kinlearn.body.kinematics import kinematics
    from kinlearn.data.problems import ProblemSet
    from kinlearn.training.obstacle_path import _batch, build_body, expert_paths, make_training_problems

    ur5 = load_robot("ur5")
    paths = make_training_problems(tmp_path / "w", 2, robot=ur5, families=("wall",), within="body")
    pool = ProblemSet.load(paths[0], robot="ur5")
    lo, hi = pool.body(ur5).limits
    assert pool.within == "body" and np.isclose(hi[0], np.pi) and hi[0] < ur5.upper[0]
    assert bool(ur5.within_limits(torch.cat((pool.start, pool.goal)), limits=(lo, hi)).all())
    assert (
        ProblemSet.load(make_training_problems(tmp_path / "r", 1, robot=ur5, families=("wall",))[0]).within
        == "robot"
    )
    with pytest.raises(ConfigError, match="within the body's limits, not the robot's"):
        make_training_problems(tmp_path / "w", 2, robot=ur5, families=("wall",))
    experts, found = expert_paths(paths[0], ur5, 4)
    assert bool(found.any()) and bool(ur5.within_limits(experts[found], 1e-9, limits=(lo, hi)).all())
    # the loss's box: a network whose knots leave ±π is charged for it there, not within ±2π
    cfg = ObstacleTrainConfig(robot="ur5", problems=tuple(map(str, paths)))
    body = build_body(cfg, ur5, pool)
    tm = ObstaclePathModel(ObstaclePathConfig.for_robot(ur5, hidden=[16], encoder=[8], candidates=2, modes=2))
    kin = kinematics(ur5)
    ef = (kin.position(pool.start), kin.position(pool.goal))
    s0, sT, scene = _batch(pool, ef, torch.arange(len(pool)), torch.zeros(len(pool), dtype=torch.bool))
    fr = torch.tensor([0.5])
    wide = torch.full((len(pool), ur5.dof), 1.5 * np.pi)
    narrow = torch.full((len(pool), ur5.dof), 0.1)
    _, t_wide = candidate_losses(tm, body, s0, sT, scene, ObstacleLossConfig(), fr, box=(-wide, wide))
    _, t_narrow = candidate_losses(tm, body, s0, sT, scene, ObstacleLossConfig(), fr, box=(-narrow, narrow))
    assert float(t_narrow["limits"].detach().sum()) > float(t_wide["limits"].detach().sum())


def test_leave_one_family_out_bookkeeping():
    """select_families expands groups, keeps order, drops the left-out family, and refuses what it
    cannot do; the groups are the families the benchmark sets and the generator know."""
    from kinlearn.data.problems import FAMILIES, FAMILY_GROUPS, LEGACY_FAMILIES, select_families
    from kinlearn.data.scenes import SCENE_FAMILIES

    assert select_families(["scenes"]) == SCENE_FAMILIES
    assert select_families("all") == FAMILIES
    assert select_families(["scenes"], ["cage"]) == tuple(f for f in SCENE_FAMILIES if f != "cage")
    assert len(select_families(["scenes"], ["cage"])) == len(SCENE_FAMILIES) - 1
    assert select_families(["cage", "scenes", "legacy"]) == (
        "cage",
        *(f for f in SCENE_FAMILIES if f != "cage"),
        *LEGACY_FAMILIES,
    )
    assert set(FAMILY_GROUPS["all"]) == set(LEGACY_FAMILIES) | set(SCENE_FAMILIES)
    with pytest.raises(ConfigError, match="unknown problem family"):
        select_families(["kitchen"])
    with pytest.raises(ConfigError, match="not among"):
        select_families(["legacy"], ["cage"])
    with pytest.raises(ConfigError, match="no family left"):
        select_families(["cage"], ["cage"])


def test_the_sparse_hinges_are_the_dense_ones(problems):
    """The collision and self-collision terms, measured only where the kernel finds spheres within the
    margin, equal the hinge over every sphere and pair, in value and gradient."""
    from kinlearn.collision.distance import self_collision_distance
    from kinlearn.training.obstacle_path import _batch, build_body

    _, ps = problems
    robot = load_robot("iiwa14")
    cfg = _tiny(problems)
    body = build_body(cfg, robot)
    tm = ObstaclePathModel(cfg.model_config(robot))
    from kinlearn.body.kinematics import kinematics

    kin = kinematics(robot)
    ef = (kin.position(ps.start), kin.position(ps.goal))
    s0, sT, scene = _batch(ps, ef, torch.arange(len(ps)), torch.zeros(len(ps), dtype=torch.bool))
    loss_cfg = ObstacleLossConfig(margin=0.1)  # wide: many spheres and pairs within it
    fr = torch.tensor([0.25, 0.75])
    _, terms = candidate_losses(tm, body, s0, sT, scene, loss_cfg, fr)
    grads = torch.autograd.grad(
        terms["collision"].sum() + terms["self_collision"].sum(), list(tm.parameters())
    )
    # The dense reference: every arm sphere against the scene, every pair.
    from kinlearn.models.obstacle_path import scene_primitives
    from kinlearn.training.obstacle_path import _dense

    mid = tm(s0, sT, *scene_primitives(scene, len(ps), s0.dtype))
    n, C = mid.shape[:2]
    knots = torch.cat(
        (
            s0[:, None, None, :7].expand(n, C, 1, 7),
            mid.clamp(tm.lower, tm.upper),
            sT[:, None, None, :7].expand(n, C, 1, 7),
        ),
        2,
    )
    centres = body(_dense(knots, fr), validate=False)
    arm = body.link > 0
    d = _scene_clearance(centres[..., arm, :].flatten(1, 2), body.radii[arm], scene, body.floor_mask[arm])
    collision = torch.relu(0.1 - d).sum(-1).view(n, C, -1).mean(-1)
    _, pair = self_collision_distance(centres, body.radii, body.pairs, per_pair=True)
    self_col = torch.relu(0.1 - pair).sum(-1).mean(-1)
    assert float(collision.detach().sum()) > 0 and float(self_col.detach().sum()) > 0
    assert torch.allclose(terms["collision"], collision, rtol=1e-5, atol=1e-7)
    assert torch.allclose(terms["self_collision"], self_col, rtol=1e-5, atol=1e-7)
    ref = torch.autograd.grad(collision.sum() + self_col.sum(), list(tm.parameters()))
    for a, b in zip(grads, ref, strict=True):
        assert torch.allclose(a, b, rtol=1e-4, atol=1e-6 * float(b.abs().max()) + 1e-9)


def test_expert_paths_solve_start_to_goal_and_are_cached(problems, tmp_path):
    """The offline sampler's targets: from each start to its goal, the same on a second call (read from
    the cache beside the set), made again for another number of knots; resampled by arc length."""
    import shutil

    from kinlearn.training.obstacle_path import expert_paths

    path = tmp_path / "train.npz"
    shutil.copy(problems[0], path)
    robot = load_robot("iiwa14")
    paths, found = expert_paths(path, robot, 6)
    pset = problems[1]
    assert paths.shape == (len(pset), 7, 7) and found.dtype == torch.bool and int(found.sum()) >= 4
    assert torch.allclose(paths[found, 0], pset.start[found].double())
    assert torch.allclose(paths[found, -1], pset.goal[found].double())
    cache = tmp_path / "train.experts6.npz"
    assert cache.is_file()
    again, found2 = expert_paths(path, robot, 6)
    assert torch.equal(again, paths) and torch.equal(found2, found)
    assert expert_paths(path, robot, 4)[0].shape[1] == 5 and (tmp_path / "train.experts4.npz").is_file()


def test_distillation_pulls_the_nearest_candidate_and_is_recorded(problems, tmp_path):
    """With imitation > 0 training logs the nearest candidate's knot difference to the sampler's path,
    lowers it, and the checkpoint (and its export) say the network was distilled; without it they do
    not."""
    from kinlearn.models.obstacle_path import export_obstacle_model

    cfg = _tiny(problems, iterations=30, loss=ObstacleLossConfig(imitation=50.0))
    tm = train_obstacle_model(cfg, tmp_path / "d", progress=False)
    logs = [json.loads(x) for x in (tmp_path / "d" / "metrics.jsonl").read_text().splitlines()]
    imit = [x["train/imitation"] for x in logs if "train/imitation" in x]
    assert len(imit) >= 2 and imit[-1] < imit[0]
    assert tm.distilled == "sampler" == load_obstacle_model(tmp_path / "d" / "tm_obstacles.pt").distilled
    export_obstacle_model(tmp_path / "d" / "tm_obstacles.pt", tmp_path / "exported.pt")
    assert load_obstacle_model(tmp_path / "exported.pt").distilled == "sampler"
    plain = train_obstacle_model(_tiny(problems, iterations=2), tmp_path / "p", progress=False)
    assert (
        plain.distilled is None and load_obstacle_model(tmp_path / "p" / "tm_obstacles.pt").distilled is None
    )
    # A self-supervised run's record is what it was before distillation existed (runs made then resume).
    assert "imitation" not in _tiny(problems).to_dict()["loss"]
    assert cfg.to_dict()["loss"]["imitation"] == 50.0
    assert ObstacleTrainConfig.from_dict(_tiny(problems).to_dict()) == _tiny(problems)


def test_solvable_only_trains_on_what_the_sampler_solves(problems, tmp_path):
    """The feasibility filter: training keeps the problems whose offline sampler path was found (all of
    them when it finds all), records itself in the run's config only when on, and is refused when it
    would leave nothing."""
    import shutil

    from kinlearn.training.obstacle_path import expert_paths

    path = tmp_path / "train.npz"
    shutil.copy(problems[0], path)
    cfg = _tiny((path,), iterations=2, solvable_only=True)
    assert cfg.to_dict()["solvable_only"] is True and "solvable_only" not in _tiny(problems).to_dict()
    tm = train_obstacle_model(cfg, tmp_path / "run", progress=False)
    _, found = expert_paths(path, load_robot("iiwa14"), tm.config.steps)
    assert tm.distilled is None and int(found.sum()) >= 4  # a filter, not a teacher
    kept = {f for f, ok in zip(problems[1].family.tolist(), found.tolist(), strict=True) if ok}
    assert len(tm.families) == len(kept)


def test_solvable_only_refuses_a_pool_the_sampler_solves_none_of(problems, tmp_path):
    """Every start inside an obstacle: the sampler solves nothing, and the filter says so (a
    ConfigError) instead of training on an empty pool."""
    import dataclasses

    from kinlearn.collision import Scene

    pset = problems[1]
    n = len(pset)
    walled = Scene.from_spheres([[0.0, 0.0, 0.3, 0.5]], floor=0.0).expand(n)  # the base inside a ball
    dataclasses.replace(pset, scene=walled).save(tmp_path / "blocked.npz")
    with pytest.raises(ConfigError, match="solved none"):
        train_obstacle_model(
            _tiny((tmp_path / "blocked.npz",), iterations=1, solvable_only=True),
            tmp_path / "run",
            progress=False,
        )


@pytest.mark.parametrize("flag", [["--imitation", "-1"], ["--imitation", "nan"]])
def test_train_obstacle_planner_refuses_a_bad_imitation_weight(flag, tmp_path, capsys):
    from kinlearn.cli.main import main

    args = ["train-obstacle-planner", "--problems-per-family", "1", "--iterations", "1", *flag]
    with pytest.raises(SystemExit) as exit_:
        main([*args, "--run-dir", str(tmp_path / "run"), "--no-progress"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "--imitation" in err and "finite number ≥ 0" in err
    assert not (tmp_path / "run").exists()  # refused before anything is written
