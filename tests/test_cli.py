"""The kinlearn command: help on every subcommand, tiny runs that write config.json and outputs."""

import argparse
import hashlib
import json
import shutil

import pytest
import torch

from kinlearn.cli.common import add_command, register_subcommand
from kinlearn.cli.main import build_parser, main
from kinlearn.data.babbling import BabblingConfig, load_transitions
from kinlearn.data.endpoints import EndpointConfig, load_endpoints, make_endpoints, save_endpoints
from kinlearn.errors import ConfigError, DatasetError
from kinlearn.models.chain import ChainFM
from kinlearn.models.forward_inverse import LearnedFM, LearnedIM, load_fm, load_im
from kinlearn.planning.planner import DEFAULT_CHECKPOINTS, Planner
from kinlearn.training.tm import tm_preset, train_tm

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
    # the models' widths from the command line, recorded in the run and the checkpoint
    narrow = ["--preset", "improved", "--epochs", "1", "--no-progress", "--validate", "0", *data]
    assert main(["train-fm", *narrow, "--fk-hidden", "16", "8", "--run-dir", str(tmp_path / "fm16")]) == 0
    assert main(["train-im", *narrow, "--hidden", "12", "--run-dir", str(tmp_path / "im12")]) == 0
    assert load_fm(tmp_path / "fm16" / "fm.pt").config.fk_hidden == (16, 8)
    assert load_im(tmp_path / "im12" / "im.pt").config.hidden == (12,)
    assert json.loads((tmp_path / "fm16" / "config.json").read_text())["model"]["fk_hidden"] == [16, 8]
    capsys.readouterr()
    assert main(["train-fm", *common, *data, "--fk-hidden", "16", "--run-dir", str(tmp_path / "no")]) == 2
    assert "has none" in capsys.readouterr().err and not (tmp_path / "no").exists()


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
        from kinlearn.cli import common as cli

        cli._SUBCOMMANDS.remove(add)


# --------------------------------------------------------------------------------------------------
# The run-directory policy on every command (issue cases 1, 2) and degenerate inputs (case 4)
# --------------------------------------------------------------------------------------------------


def _sha(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Finished tiny runs of every stage: babbling data, two FMs, an IM, endpoints, a TM."""
    root = tmp_path_factory.mktemp("runs")
    assert main(["babble", "--transitions", "3000", "--walkers", "50", "--run-dir", str(root / "b")]) == 0
    tiny = ["--preset", "tiny", "--epochs", "1", "--no-progress", "--validate", "0"]
    data = ["--data", str(root / "b" / "babbling.npz")]
    assert main(["train-fm", *tiny, *data, "--run-dir", str(root / "fm")]) == 0
    assert main(["train-fm", *tiny, *data, "--seed", "7", "--run-dir", str(root / "fm-other")]) == 0
    assert main(["train-im", *tiny, *data, "--run-dir", str(root / "im")]) == 0
    assert main(["make-endpoints", "--n", "48", "--heldout", "8", "--run-dir", str(root / "ep")]) == 0
    tm = ["train-tm", "--endpoints", str(root / "ep"), "--epochs", "1", "--batch-size", "16", "--no-progress"]
    tm += ["--fm-checkpoint", str(root / "fm" / "fm.pt"), "--im-checkpoint", str(root / "im" / "im.pt")]
    assert main([*tm, "--run-dir", str(root / "tm")]) == 0
    return root, tiny, data, tm


def test_a_finished_run_is_never_changed_silently(runs, capsys):
    """Case 1: train-tm with another FM on a finished run is refused before anything is written."""
    root, tiny, data, tm = runs
    before = {p.name: _sha(p) for p in (root / "tm").iterdir() if p.is_file()}
    other = [*tm, "--fm-checkpoint", str(root / "fm-other" / "fm.pt"), "--run-dir", str(root / "tm")]
    capsys.readouterr()
    assert main(other) == 2
    assert "already holds a train-tm run" in capsys.readouterr().err
    assert main([*other, "--resume"]) == 2  # resuming through another FM: the difference is named
    assert "models.fm.sha256" in capsys.readouterr().err
    assert {p.name: _sha(p) for p in (root / "tm").iterdir() if p.is_file()} == before
    # train-fm into a finished run: refused, its model and config.json untouched
    fm_before = {n: _sha(root / "fm" / n) for n in ("fm.pt", "config.json")}
    assert main(["train-fm", *tiny, *data, "--seed", "3", "--run-dir", str(root / "fm")]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert {n: _sha(root / "fm" / n) for n in ("fm.pt", "config.json")} == fm_before
    # every command that writes a run directory follows the same policy
    ep = ["make-endpoints", "--n", "8", "--heldout", "0", "--run-dir", str(root / "ep")]
    babble_again = ["babble", "--transitions", "100", "--run-dir", str(root / "b")]
    validate = ["validate", "--fm", "analytic", "--n", "100", "--run-dir", str(root / "val")]
    assert main(validate) == 0
    for argv in (ep, babble_again, validate, ["reproduce", "--smoke", "--run-dir", str(root / "tm")]):
        assert main(argv) == 2, argv
        assert "error:" in capsys.readouterr().err


def test_resume_with_an_identical_config_continues_and_overwrite_replaces(runs, tmp_path, capsys):
    _, tiny, data, _ = runs
    run = ["train-fm", *tiny, *data, "--run-dir", str(tmp_path / "fm")]
    assert main(run) == 0
    first = _sha(tmp_path / "fm" / "fm.pt")
    assert main([*run, "--resume"]) == 0  # finished, same config: nothing to train
    assert _sha(tmp_path / "fm" / "fm.pt") == first
    (tmp_path / "fm" / "notes.txt").write_text("mine")
    assert main([*run, "--seed", "4", "--overwrite"]) == 0
    assert _sha(tmp_path / "fm" / "fm.pt") != first
    assert json.loads((tmp_path / "fm" / "config.json").read_text())["train"]["seed"] == 4
    assert (tmp_path / "fm" / "notes.txt").read_text() == "mine"
    assert main([*run, "--resume", "--overwrite"]) == 2
    assert "exclude each other" in capsys.readouterr().err


def test_each_stage_resumes_alone(runs, tmp_path):
    """train-im --through-fm keeps each stage's checkpoint, so a finished run resumes to the same IM;
    a finished train-tm run resumed with the same options stays as it is."""
    root, tiny, data, tm = runs
    through = ["--through-fm", str(root / "fm" / "fm.pt"), "--through-fm-epochs", "1"]
    run = ["train-im", *tiny, *data, *through, "--run-dir", str(tmp_path / "im")]
    assert main(run) == 0
    assert (tmp_path / "im" / "supervised" / "im.pt").is_file()
    refined = _sha(tmp_path / "im" / "im.pt")
    assert refined == _sha(tmp_path / "im" / "through-fm" / "im.pt")
    assert main([*run, "--resume"]) == 0
    assert _sha(tmp_path / "im" / "im.pt") == refined
    before = _sha(root / "tm" / "tm.pt")
    assert main([*tm, "--run-dir", str(root / "tm"), "--resume"]) == 0
    assert _sha(root / "tm" / "tm.pt") == before


@pytest.mark.parametrize(
    ("change", "named"),
    [
        (["--lr", "0.01"], "train.optim.lr: 0.003 → 0.01"),
        (["--preset", "paper"], "model."),
        (["--data", "OTHER"], "data.sha256"),
        (["--epochs", "2"], "train.epochs: 1 → 2"),
    ],
)
def test_resume_refuses_a_changed_config(runs, tmp_path, capsys, change, named):
    """Case 2: a new --lr, --data or --preset on --resume is refused, naming what differs."""
    _, tiny, data, _ = runs
    run = ["train-fm", *tiny, *data, "--run-dir", str(tmp_path / "fm")]
    assert main(run) == 0
    before = _sha(tmp_path / "fm" / "config.json")
    if change[0] == "--data":
        other = tmp_path / "other"
        babble = ["babble", "--transitions", "2000", "--walkers", "40", "--seed", "5"]
        assert main([*babble, "--run-dir", str(other)]) == 0
        change = ["--data", str(other / "babbling.npz")]
    capsys.readouterr()
    assert main([*run, *change, "--resume"]) == 2
    err = capsys.readouterr().err
    assert "another configuration" in err and named in err, err
    assert _sha(tmp_path / "fm" / "config.json") == before


def test_export_never_overwrites_the_shipped_planner_by_default(runs, tmp_path, capsys):
    root, *_ = runs
    shipped = DEFAULT_CHECKPOINTS / "iiwa14"
    before = {p.name: _sha(p) for p in shipped.glob("*.pt")}
    with pytest.raises(SystemExit) as exc:
        main(["export", "--model", str(root / "tm")])
    assert exc.value.code == 2
    assert "--out" in capsys.readouterr().err
    assert main(["export", "--model", str(root / "tm"), "--to-package"]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert {p.name: _sha(p) for p in shipped.glob("*.pt")} == before
    # into a folder: it loads on its own, records its FM/IM by hash; a second export is refused
    out = tmp_path / "planner"
    assert main(["export", "--model", str(root / "tm"), "--out", str(out)]) == 0
    payload = torch.load(out / "tm.pt", weights_only=True)
    assert payload["depends"]["fm"] == {"path": "fm.pt", "sha256": _sha(out / "fm.pt")}
    # the planner's tm.pt holds the model's own config: no optimiser, loss, folder or training state
    assert payload["extra"] == {} and set(payload["config"]) == {
        "tm",
        "fm",
        "im",
        "im_iterations",
        "im_damping",
    }
    assert main(["export", "--model", str(root / "tm"), "--out", str(out)]) == 2
    assert main(["export", "--model", str(root / "tm"), "--out", str(out), "--overwrite"]) == 0
    # An identified chain in the run folder travels with the export, unchanged, and solves position goals.
    with_chain = tmp_path / "tm_chain"
    shutil.copytree(root / "tm", with_chain)
    shutil.copy(shipped / "chain.pt", with_chain / "chain.pt")
    assert main(["export", "--model", str(with_chain), "--out", str(tmp_path / "p2")]) == 0
    assert _sha(tmp_path / "p2" / "chain.pt") == _sha(shipped / "chain.pt")
    assert isinstance(Planner.load(tmp_path / "p2").chain, ChainFM)


def test_degenerate_endpoint_sets(tmp_path, capsys):
    """Case 4: --n 0 is rejected; --heldout 0 trains without held-out metrics; NaN is a dataset error."""
    with pytest.raises(SystemExit):
        main(["make-endpoints", "--n", "0", "--run-dir", str(tmp_path / "none")])
    assert "--n: expected an integer ≥ 1, got '0'" in capsys.readouterr().err
    assert not (tmp_path / "none").exists()
    with pytest.raises(ConfigError, match="positive"):
        EndpointConfig(n=0)
    with pytest.raises(ConfigError, match="min_distance"):
        EndpointConfig(min_distance=float("nan"))
    with pytest.raises(DatasetError, match="empty"):
        train_tm(
            tm_preset("default", fm="analytic", im="analytic"),
            tmp_path / "t",
            make_endpoints(EndpointConfig(n=4)).split(0)[0],
            progress=False,
        )
    ep = tmp_path / "ep"
    assert main(["make-endpoints", "--n", "24", "--heldout", "0", "--run-dir", str(ep)]) == 0
    assert not (ep / "endpoints_heldout.npz").exists()
    analytic = ["train-tm", "--fm", "analytic", "--im", "analytic", "--epochs", "1", "--no-progress"]
    assert main([*analytic, "--endpoints", str(ep), "--run-dir", str(tmp_path / "tm")]) == 0
    # a NaN in an endpoints file: reported as a broken file when loaded, not as divergence
    pairs = load_endpoints(ep / "endpoints_train.npz")
    pairs.start[3, 2] = float("nan")
    bad = tmp_path / "bad"
    save_endpoints(pairs, bad / "endpoints_train.npz")
    with pytest.raises(DatasetError, match="NaN"):
        load_endpoints(bad / "endpoints_train.npz")
    capsys.readouterr()
    assert main([*analytic, "--endpoints", str(bad), "--run-dir", str(tmp_path / "tm-bad")]) == 2
    err = capsys.readouterr().err
    assert "NaN" in err and "learning rate" not in err
    assert not (tmp_path / "tm-bad").exists()  # refused before anything was written


def test_babbling_walkers_are_rejected_not_clamped(capsys, tmp_path):
    with pytest.raises(SystemExit):
        main(["babble", "--walkers", "0", "--run-dir", str(tmp_path / "b")])
    assert "--walkers: expected an integer ≥ 1" in capsys.readouterr().err
    with pytest.raises(ConfigError, match="walker"):
        BabblingConfig.for_transitions(1000, walkers=0)
    with pytest.raises(ConfigError, match="transition"):
        BabblingConfig.for_transitions(0)


# --------------------------------------------------------------------------------------------------
# Learning rates (case 5) and every numeric option
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("command", ["train-fm", "train-im", "train-tm"])
@pytest.mark.parametrize("lr", ["-1", "0", "nan", "inf", "fast"])
def test_learning_rates_must_be_positive_finite_numbers(command, lr, capsys):
    extra = ["--endpoints", "."] if command == "train-tm" else []
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args([command, *extra, "--lr", lr])
    assert exc.value.code == 2
    assert f"argument --lr: expected a finite number > 0, got '{lr}'" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv",
    [
        ["babble", "--transitions", "0"],
        ["babble", "--max-step", "-0.1"],
        ["babble", "--retarget-prob", "1.5"],
        ["babble", "--threads", "0"],
        ["train-fm", "--epochs", "0"],
        ["train-fm", "--batch-size", "-4"],
        ["train-fm", "--val-fraction", "1"],
        ["train-fm", "--validate", "-1"],
        ["train-im", "--through-fm-epochs", "0"],
        ["train-im", "--action-weight", "-1"],
        ["validate", "--n", "0"],
        ["validate", "--im-iterations", "0"],
        ["make-endpoints", "--heldout", "-1"],
        ["make-endpoints", "--min-distance", "inf"],
        ["make-endpoints", "--start-spread", "-1"],
        ["train-tm", "--endpoints", ".", "--epochs", "0"],
        ["train-tm", "--endpoints", ".", "--alpha", "1"],
        ["train-tm", "--endpoints", ".", "--batch-size", "1.5"],
        ["reproduce", "--workers", "0"],
    ],
)
def test_numeric_options_are_validated_with_a_clear_message(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(argv)
    assert exc.value.code == 2
    assert f"argument {argv[-2]}: expected " in capsys.readouterr().err


def test_train_tm_zero_values_are_values_and_a_huge_rate_is_divergence(runs, tmp_path, capsys):
    """`--alpha 0` is used, not replaced by the preset's; lr = 1e9 is caught though the loss stays finite."""
    root, *_ = runs
    analytic = ["train-tm", "--endpoints", str(root / "ep"), "--fm", "analytic", "--im", "analytic"]
    analytic += ["--epochs", "1", "--batch-size", "16", "--no-progress"]
    argv = [*analytic, "--optimizer", "rmsprop", "--alpha", "0", "--run-dir", str(tmp_path / "a")]
    assert main(argv) == 0
    optim = json.loads((tmp_path / "a" / "config.json").read_text())["tm"]["optim"]
    assert optim["name"] == "rmsprop" and optim["alpha"] == 0.0
    capsys.readouterr()
    assert main([*analytic, "--epochs", "3", "--lr", "1e9", "--run-dir", str(tmp_path / "b")]) == 2
    assert "diverged" in capsys.readouterr().err


# --------------------------------------------------------------------------------------------------
# Help and options (case 7), exit status
# --------------------------------------------------------------------------------------------------


def _subparsers():
    parser = build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return sub.choices


def test_every_option_has_help():
    for name, p in _subparsers().items():
        if name == "plan":
            continue
        missing = [a.dest for a in p._actions if not a.help]
        assert missing == [], f"{name}: options without help: {missing}"


def test_validate_help_states_its_real_default_seed(capsys):
    assert build_parser().parse_args(["validate"]).seed == 10_000
    with pytest.raises(SystemExit):
        main(["validate", "--help"])
    assert "(default: 10000)" in capsys.readouterr().out


def test_export_takes_no_seed_or_run_dir(capsys):
    for option in (["--seed", "1"], ["--run-dir", "x"]):
        with pytest.raises(SystemExit) as exc:
            build_parser().parse_args(["export", "--model", ".", "--out", "o", *option])
        assert exc.value.code == 2
        assert "unrecognized arguments" in capsys.readouterr().err


def test_interrupted_commands_exit_with_130(capsys):
    def add(sub):
        add_command(sub, "stop", "Get interrupted.", lambda args: (_ for _ in ()).throw(KeyboardInterrupt))

    register_subcommand(add)
    try:
        assert main(["stop"]) == 130
        assert "interrupted" in capsys.readouterr().err
    finally:
        from kinlearn.cli import common as cli

        cli._SUBCOMMANDS.remove(add)
