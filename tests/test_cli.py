"""The kinlearn command: help on every subcommand, tiny runs that write config.json and outputs."""

import json

import pytest
import torch

from kinlearn.babbling import load_transitions
from kinlearn.cli import add_command, build_parser, main, register_subcommand
from kinlearn.models import LearnedFM, LearnedIM, load_fm, load_im

COMMANDS = ("babble", "train-fm", "train-im", "validate")


@pytest.fixture(autouse=True)
def keep_threads():
    n = torch.get_num_threads()
    yield
    torch.set_num_threads(n)


def test_top_level_help(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for name in COMMANDS:
        assert name in out


@pytest.mark.parametrize("name", COMMANDS)
def test_subcommand_help(name, capsys):
    with pytest.raises(SystemExit) as exc:
        main([name, "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for option in ("--robot", "--seed", "--run-dir"):
        assert option in out


def test_babble_writes_data_and_config(tmp_path, capsys):
    run = tmp_path / "b"
    assert (
        main(["babble", "--robot", "ur5", "--transitions", "1000", "--walkers", "10", "--run-dir", str(run)])
        == 0
    )
    cfg = json.loads((run / "config.json").read_text())
    assert (
        cfg["command"] == "babble" and cfg["babbling"]["robot"] == "ur5" and cfg["babbling"]["steps"] == 100
    )
    data = load_transitions(run / "babbling.npz", robot="ur5")
    assert len(data) == 1000 and data.s.shape[1] == 9
    assert "1,000 transitions" in capsys.readouterr().out


def test_tiny_train_and_validate(tmp_path, capsys):
    data_dir = tmp_path / "data"
    main(["babble", "--transitions", "4000", "--walkers", "100", "--run-dir", str(data_dir)])
    common = ["--preset", "tiny", "--epochs", "1", "--no-progress", "--validate", "2000"]
    data = ["--data", str(data_dir / "babbling.npz")]
    assert main(["train-fm", *common, *data, "--run-dir", str(tmp_path / "fm")]) == 0
    assert main(["train-im", *common, "--transitions", "3000", "--run-dir", str(tmp_path / "im")]) == 0
    for kind in ("fm", "im"):
        run = tmp_path / kind
        cfg = json.loads((run / "config.json").read_text())
        assert (
            cfg["command"] == f"train-{kind}"
            and cfg["train"]["epochs"] == 1
            and cfg["model"]["robot"] == "iiwa14"
        )
        assert (run / "metrics.jsonl").is_file() and (run / "validation.json").is_file()
    assert isinstance(load_fm(tmp_path / "fm" / "fm.pt", robot="iiwa14"), LearnedFM)
    assert isinstance(load_im(tmp_path / "im" / "im.pt"), LearnedIM)
    capsys.readouterr()
    args = ["validate", "--fm", str(tmp_path / "fm" / "fm.pt"), "--im", "analytic", "--n", "2000"]
    assert main([*args, "--run-dir", str(tmp_path / "val")]) == 0
    out = capsys.readouterr().out
    assert "| FM ef MAE (mm) |" in out and "| IM action MAE (rad) |" in out
    res = json.loads((tmp_path / "val" / "validation.json").read_text())
    assert res["n"] == 2000 and "fm_run_config" in res
    assert (tmp_path / "val" / "config.json").is_file() and (tmp_path / "val" / "validation.md").is_file()
    # train-im refined through the frozen FM: a second stage in its own folder, im.pt replaced
    through = ["--through-fm", str(tmp_path / "fm" / "fm.pt"), "--through-fm-epochs", "1"]
    assert main(["train-im", *common, *data, *through, "--run-dir", str(tmp_path / "im2")]) == 0
    assert (tmp_path / "im2" / "through-fm" / "im.pt").is_file()
    refined = load_im(tmp_path / "im2" / "im.pt")
    staged = load_im(tmp_path / "im2" / "through-fm" / "im.pt")
    assert all(
        torch.equal(a, b)
        for a, b in zip(refined.state_dict().values(), staged.state_dict().values(), strict=True)
    )


def test_errors_are_reported_not_raised(tmp_path, capsys):
    assert main(["validate", "--fm", str(tmp_path / "missing.pt"), "--run-dir", str(tmp_path / "v")]) == 2
    assert "no checkpoint file" in capsys.readouterr().err
    assert main(["validate", "--run-dir", str(tmp_path / "v")]) == 2
    with pytest.raises(SystemExit):
        main(["train-fm", "--preset", "huge"])


def test_subcommands_can_be_added():
    seen = []

    def add(sub):
        p = add_command(sub, "hello", "Say hello.", lambda args: seen.append(args.robot) or 0)
        p.add_argument("--loud", action="store_true")

    register_subcommand(add)
    try:
        parser = build_parser()
        args = parser.parse_args(["hello", "--robot", "panda", "--loud"])
        assert args.loud and args.command == "hello"
        assert main(["hello", "--robot", "panda", "--run-dir", "unused"]) == 0
        assert seen == ["panda"]
    finally:
        from kinlearn import cli

        cli._SUBCOMMANDS.remove(add)
