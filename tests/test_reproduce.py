"""The whole pipeline on a tiny preset, and the planning-stage CLI."""

import json

import pytest
import torch

from kinlearn.cli.main import main
from kinlearn.errors import ConfigError, MissingDependencyError
from kinlearn.evaluation.jobs import run_jobs
from kinlearn.evaluation.reproduce import OPTIMIZER_SWEEP, _job, preset_config, reproduce


@pytest.fixture(scope="module")
def smoke(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce")
    cfg = preset_config("smoke", transitions=5_000, train_pairs=48, heldout_pairs=32)
    return out, reproduce(cfg, out, progress=False)


@pytest.mark.slow
def test_reproduce_smoke_writes_tables_and_figures(smoke):
    out, res = smoke
    assert (out / "results.md").is_file() and (out / "results.json").is_file()
    assert set(res["table1"]) == set(OPTIMIZER_SWEEP)
    # Every row is judged on the same held-out pairs as the baselines.
    pairs_distance = res["baselines"]["joint interpolation"]["endpoint_distance"]["mean"]
    for row in res["table1"].values():
        assert row["heldout"]["endpoint_distance"]["mean"] == pytest.approx(pairs_distance, rel=1e-5)
        assert row["final_l_tm"]["mean"] > 0.0 and row["final_l_tm"]["std"] >= 0.0
    assert len(res["ablation"]) == 4
    # The Cartesian baseline's waypoints lie on the straight line; joint interpolation ends at the goal.
    assert res["baselines"]["Cartesian line + DLS IK"]["mean_angle"]["min"] > 179.0
    assert res["baselines"]["joint interpolation"]["state_success"]["mean"] == 1.0
    parity = res["reference_parity"]
    assert parity["final_l_tm"] > 0.0
    assert parity["heldout"]["endpoint_distance"]["mean"] == pytest.approx(pairs_distance, rel=1e-5)
    md = (out / "results.md").read_text()
    assert "Table 1" in md and "Table 2" in md and "paper #4" in md
    # The FM × IM ablation: four FM kinds, three IM kinds; the exact pair reaches every position goal,
    # an MLP FM has no Jacobian of positions to solve on, and every cell of the paper's task is filled.
    fm_im = res["fm_im"]
    assert len(fm_im) == 4 and all(set(row) == {"mlp", "analytic", "through"} for row in fm_im.values())
    assert fm_im["analytic FK"]["through"]["position"]["success"] == 1.0
    assert next(iter(fm_im.values()))["through"] == {"position": None, "task": None}
    assert all(c["task"] is not None for row in list(fm_im.values())[1:] for c in row.values())
    assert "FM × IM ablation" in md and (out / "models" / "chain.pt").is_file()
    pytest.importorskip("matplotlib")
    for fig in ("fig3_trajectories.png", "fig4_histograms.png"):
        assert (out / fig).stat().st_size > 10_000
    assert json.loads((out / "results.json").read_text())["best_table1"] in OPTIMIZER_SWEEP


@pytest.mark.slow
def test_overwrite_knows_everything_reproduce_writes(smoke):
    """`reproduce --overwrite` deletes the outputs it knows of: every one the run writes (workspace/ was
    left behind, and the new run then failed partway)."""
    from kinlearn.cli.evaluate import REPRODUCE_OUTPUTS

    out, _ = smoke
    written = {p.name for p in out.iterdir()} - {"config.json"}
    assert written and written <= set(REPRODUCE_OUTPUTS), written - set(REPRODUCE_OUTPUTS)


@pytest.mark.slow
def test_the_main_job_records_domain_warnings_instead_of_printing_them(smoke):
    """Held-out pairs outside the training pairs' range are the experiment's, not its user's to mend."""
    import warnings

    from kinlearn.data.endpoints import load_endpoints
    from kinlearn.errors import DomainWarning
    from kinlearn.evaluation.reproduce import _evaluate_run

    out, _ = smoke
    heldout = load_endpoints(out / "endpoints_heldout.npz")
    run_dir = next(p for p in sorted((out / "tm").iterdir()) if (p / "tm.pt").is_file())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = _evaluate_run(run_dir.name, run_dir, heldout, 0.0)
    assert not [w for w in caught if issubclass(w.category, DomainWarning)]
    assert isinstance(result["domain_notes"], list)


def test_reproduce_config_errors():
    with pytest.raises(ConfigError, match="quick"):
        preset_config("huge")
    with pytest.raises(ConfigError, match="local"):
        run_jobs(_job, [], 1, "slurm")


@pytest.mark.slow
def test_ray_backend_runs_or_says_what_is_missing(smoke):
    out, _ = smoke
    job = {
        "kind": "tm",
        "name": "ray-job",
        "config": json.loads((out / "tm" / "ablation-fm_analytic-im_analytic" / "config.json").read_text()),
        "run_dir": str(out / "tm" / "ray-job"),
        "train": str(out / "endpoints_train.npz"),
        "heldout": str(out / "endpoints_heldout.npz"),
        "limit": 16,
    }
    job["config"]["epochs"] = 1
    try:
        import ray  # noqa: F401
    except ImportError:
        with pytest.raises(MissingDependencyError, match=r"kinlearn\[ray\]"):
            run_jobs(_job, [job], 1, "ray")
        return
    (result,) = run_jobs(_job, [job], 1, "ray")
    assert result["name"] == "ray-job" and result["heldout"]["mean_angle"]["mean"] > 0


def test_cli_endpoints_train_tm_plan_export(tmp_path, capsys):
    ep, tm, out = tmp_path / "ep", tmp_path / "tm", tmp_path / "export"
    assert main(["make-endpoints", "--n", "64", "--heldout", "16", "--run-dir", str(ep)]) == 0
    assert (ep / "endpoints_train.npz").is_file() and (ep / "config.json").is_file()
    args = ["train-tm", "--endpoints", str(ep), "--fm", "analytic", "--im", "analytic", "--epochs", "1"]
    assert main([*args, "--run-dir", str(tm), "--no-progress"]) == 0
    assert "held-out" in capsys.readouterr().out
    start, goal = "0.3,0.45,0,-1.35,0,1.05,0", "0.6,1.1,0,-0.7,0,0.9,0"
    # The paper's waypoint TM does not steer the joints to the goal's: the plan misses the goal state,
    # and the command says so with exit status 1.
    assert main(["plan", "--model", str(tm), "--start", start, "--goal", goal]) == 1
    text = capsys.readouterr().out
    assert "goal error" in text and "NO" in text and "0/1 plans succeeded" in text
    assert main(["export", "--model", str(tm), "--out", str(out)]) == 0
    payload = torch.load(out / "tm.pt", weights_only=True)
    assert payload["extra"] == {}  # no optimiser state in an exported planner
    # learned models from their own run directories, copied into the TM's run
    tiny = ["--preset", "tiny", "--epochs", "1", "--transitions", "2000", "--no-progress", "--validate", "0"]
    assert main(["train-fm", *tiny, "--run-dir", str(tmp_path / "fm")]) == 0
    assert main(["train-im", *tiny, "--run-dir", str(tmp_path / "im")]) == 0
    ckpts = [
        "--fm-checkpoint",
        str(tmp_path / "fm" / "fm.pt"),
        "--im-checkpoint",
        str(tmp_path / "im" / "im.pt"),
    ]
    learned = ["train-tm", "--endpoints", str(ep), "--epochs", "1", *ckpts, "--no-progress"]
    assert main([*learned, "--run-dir", str(tmp_path / "tm-learned")]) == 0
    assert (tmp_path / "tm-learned" / "fm.pt").is_file() and (tmp_path / "tm-learned" / "im.pt").is_file()
    assert main(["plan", "--model", str(tmp_path / "tm-learned"), "--start", start, "--goal", goal]) in (0, 1)
    assert "plans succeeded" in capsys.readouterr().out
    # bad input: a missing checkpoint, a joint outside its limits: clear errors with exit status 2
    with pytest.raises(SystemExit) as exc:  # refused as the command line is read: nothing written
        main([*args, "--fm-checkpoint", str(tmp_path / "nope.pt"), "--run-dir", str(tmp_path / "x")])
    assert exc.value.code == 2 and "no such file" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
    assert main(["plan", "--model", str(tm), "--start", "0,3,0,0,0,0,0", "--goal", goal]) == 2
    assert "iiwa_joint_2" in capsys.readouterr().err


def test_seeds_merge_into_a_mean_and_a_spread_over_seeds():
    from kinlearn.evaluation.reproduce import _merge, _over_seeds_table

    seeds = [
        {
            "mean_angle": {"mean": 150.0, "std": 5.0},
            "success": {"mean": 0.5, "std": 0.5, "rate": 0.5},
            "n": 9,
        },
        {
            "mean_angle": {"mean": 160.0, "std": 7.0},
            "success": {"mean": 0.7, "std": 0.4, "rate": 0.7},
            "n": 9,
        },
    ]
    merged = _merge(seeds)
    assert merged["mean_angle"] == {"mean": 155.0, "std": 6.0, "seed_std": 5.0, "seeds": 2}
    assert merged["success"]["rate"] == pytest.approx(0.6) and merged["success"]["seed_std"] == pytest.approx(
        0.1
    )
    table = _over_seeds_table({"#4": merged})
    assert "| #4 | 2 |" in table and "155.0 ± 5.0" in table and "60.0 ± 10.0%" in table
