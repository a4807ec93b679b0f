"""The command line refuses what it cannot do before it writes anything: files checked as the command
line is read (exit status 2), inputs read before training, and divergence reported alike by every
trainer."""

from __future__ import annotations

import pytest

from kinlearn.cli.main import main

START, GOAL = "0.3,0.45,0,-1.35,0,1.05,0", "0.6,1.1,0,-0.7,0,0.9,0"


def _refused_at_parse(argv, capsys, match):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    err = capsys.readouterr().err
    assert exc.value.code == 2 and match in err, err


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["reproduce", "--smoke", "--robot", "nope"], "unknown robot 'nope'"),
        (["train-obstacle-planner", "--body-checkpoint", "{missing}"], "no such file"),
        (["train-obstacle-planner", "--init-checkpoint", "{missing}"], "no such file"),
        (["train-obstacle-planner", "--problems-dir", "{file}"], "is a file, not a folder"),
        (["train-obstacle-planner", "--planner", "{file}"], "is a file, not a folder"),
        (["train-body", "--data", "{missing}"], "no such file"),
        (["train-body", "--problems", "{missing}"], "no such file"),
        (["train-fm", "--data", "{folder}"], "is a folder, not a file"),
        (["train-fm", "--seed", str(2**70)], "argument --seed: expected an integer ≥ 0 and ≤ 4294967295"),
        (["train-fm", "--seed", "-1"], "argument --seed"),
        (["train-tm", "--endpoints", "{missing}"], "no such folder"),
        (["train-planner", "--fm-checkpoint", "{missing}"], "no such file"),
    ],
)
def test_a_refused_command_leaves_nothing_behind(tmp_path, capsys, argv, match):
    (tmp_path / "a_file").write_text("x")
    (tmp_path / "a_folder").mkdir()
    names = {"missing": tmp_path / "nope.pt", "file": tmp_path / "a_file", "folder": tmp_path / "a_folder"}
    argv = [a.format(**names) for a in argv]
    run_dir = tmp_path / "run"
    _refused_at_parse([*argv, "--run-dir", str(run_dir)], capsys, match)
    assert not run_dir.exists()


def test_outputs_under_a_file_are_refused_before_planning(tmp_path, capsys):
    (tmp_path / "a_file").write_text("x")
    bad = str(tmp_path / "a_file" / "plan.csv")
    _refused_at_parse(["plan", "--start", START, "--goal", GOAL, "--timed", bad], capsys, "is a file")
    gif = str(tmp_path / "a_file" / "plan.gif")
    _refused_at_parse(["view", "--start", START, "--goal", GOAL, "--gif", gif], capsys, "is a file")


def test_train_body_reads_its_problems_before_training(tmp_path, capsys):
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a problem set")
    run_dir = tmp_path / "body"
    argv = [
        "train-body",
        "--problems",
        str(junk),
        "--epochs",
        "1",
        "--samples",
        "100",
        "--run-dir",
        str(run_dir),
    ]
    assert main([*argv, "--no-progress"]) == 2
    assert "junk.npz" in capsys.readouterr().err
    assert not run_dir.exists()  # no config.json, no trained body.pt


def test_train_planner_reports_divergence_as_the_other_trainers_do(tmp_path, capsys):
    argv = ["train-planner", "--analytic-fm", "--lr", "1e6", "--iterations", "3", "--batch-size", "16"]
    argv += ["--heldout", "16", "--hidden", "16,16", "--no-progress", "--run-dir", str(tmp_path / "p")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "kinlearn train-planner: error: joint-path TM training diverged" in err
    assert "lower the learning rate" in err and "Traceback" not in err


def test_export_refuses_another_kind_of_run_and_a_partial_export_is_refused_on_load(tmp_path, capsys):
    from kinlearn.errors import CheckpointError
    from kinlearn.planning.planner import DEFAULT_CHECKPOINTS, Planner

    babble = tmp_path / "babble"
    assert main(["babble", "--transitions", "100", "--walkers", "10", "--run-dir", str(babble)]) == 0
    shipped = str(DEFAULT_CHECKPOINTS / "iiwa14")
    assert main(["export", "--model", shipped, "--out", str(babble)]) == 2  # it wrote a planner there before
    assert "holds a babble run" in capsys.readouterr().err
    assert not (babble / "tm.pt").exists()
    out = tmp_path / "planner"
    assert main(["export", "--model", shipped, "--out", str(out)]) == 0
    assert Planner.load(out).obstacle_tm is not None
    (out / "tm_obstacles.pt").unlink()  # as an export killed while writing it leaves the folder
    with pytest.raises(CheckpointError, match="obstacle_tm"):
        Planner.load(out)


def test_a_run_directory_under_a_file_is_a_typed_error_before_any_work(tmp_path, capsys):
    (tmp_path / "a_file").write_text("x")
    run_dir = tmp_path / "a_file" / "run"
    assert main(["babble", "--transitions", "100", "--walkers", "10", "--run-dir", str(run_dir)]) == 2
    assert "is a file, not a folder" in capsys.readouterr().err


@pytest.mark.parametrize("option", ["--body-checkpoint", "--init-checkpoint"])
def test_train_obstacle_planner_reads_its_models_before_writing(tmp_path, capsys, option):
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"not a checkpoint")
    run_dir = tmp_path / "run"
    argv = ["train-obstacle-planner", option, str(junk), "--iterations", "1", "--problems-per-family", "4"]
    assert main([*argv, "--run-dir", str(run_dir)]) == 2
    assert "not a readable kinlearn checkpoint" in capsys.readouterr().err
    assert not run_dir.exists()  # no config.json, no generated problems/
