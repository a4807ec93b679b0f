"""Defaults in one place: every command option that sets a config field defaults to that field's default,
and the babbling step bound is one constant that a learned FM records and a planner reads from it."""

from __future__ import annotations

import argparse
import dataclasses

import pytest

from kinlearn.cli.main import build_parser
from kinlearn.data.babbling import MAX_STEP, BabblingConfig, babble
from kinlearn.data.endpoints import EndpointConfig
from kinlearn.errors import ConfigError
from kinlearn.io import load_checkpoint
from kinlearn.models.body import BodyModelConfig
from kinlearn.models.configs import FMConfig
from kinlearn.models.forward_inverse import AnalyticFM, fm_config, load_fm
from kinlearn.models.obstacle_path import ObstaclePathConfig
from kinlearn.planning.planner import DEFAULT_CHECKPOINTS, Planner
from kinlearn.training.forward_inverse import THROUGH_FM_ACTION_WEIGHT, train_config, train_fm
from kinlearn.training.identify import IdentifyConfig
from kinlearn.training.joint_path import PLANNER_MODEL, PathTrainConfig
from kinlearn.training.loop import TrainConfig
from kinlearn.training.obstacle_path import ObstacleTrainConfig

_BABBLING = ("walkers", "max_step", "retarget_prob")

#: (command, option dest) → (config dataclass, field): the option sets that field.
FIELDS: dict[tuple[str, str], tuple[type, str]] = {
    **{("babble", f): (BabblingConfig, f) for f in (*_BABBLING, "ef_noise", "outliers", "outlier_size")},
    **{(c, f): (BabblingConfig, f) for c in ("train-fm", "train-im") for f in _BABBLING},
    **{(c, "val_fraction"): (TrainConfig, "val_fraction") for c in ("train-fm", "train-im")},
    ("validate", "max_step"): (BabblingConfig, "max_step"),
    ("validate", "retarget_prob"): (BabblingConfig, "retarget_prob"),
    ("make-endpoints", "start_spread"): (EndpointConfig, "start_spread"),
    ("make-endpoints", "min_distance"): (EndpointConfig, "min_distance"),
    **{("train-planner", f): (PathTrainConfig, f) for f in ("iterations", "batch_size", "lr")},
    **{("train-obstacle-planner", f): (ObstacleTrainConfig, f) for f in ("iterations", "batch_size", "lr")},
    ("train-obstacle-planner", "candidates"): (ObstaclePathConfig, "candidates"),
    **{
        ("train-body", f): (BodyModelConfig, f)
        for f in ("hidden", "activation", "epochs", "batch_size", "lr")
    },
    ("train-body", "samples"): (BodyModelConfig, "samples"),
    ("identify", "holdout"): (IdentifyConfig, "holdout"),
}

#: Options whose default is a named preset rather than a field's default.
PRESETS = {
    ("train-planner", "hidden"): PLANNER_MODEL["hidden"],
    ("train-planner", "modes"): PLANNER_MODEL["modes"],
    ("train-im", "action_weight"): THROUGH_FM_ACTION_WEIGHT,
    ("babble", "transitions"): BabblingConfig().transitions,
}


def _field_default(cls: type, name: str):
    (field,) = [f for f in dataclasses.fields(cls) if f.name == name]
    return field.default_factory() if field.default is dataclasses.MISSING else field.default


def _command_defaults() -> dict[tuple[str, str], object]:
    parser = build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return {(name, a.dest): a.default for name, p in sub.choices.items() for a in p._actions}


def test_every_option_that_sets_a_field_defaults_to_the_fields_default():
    defaults = _command_defaults()
    for (command, dest), (cls, name) in FIELDS.items():
        assert (command, dest) in defaults, f"{command} has no option {dest}"
        assert defaults[command, dest] == _field_default(cls, name), (command, dest)
    for key, value in PRESETS.items():
        assert defaults[key] == value, key


def test_the_shipped_planners_settings_are_the_defaults():
    # kinlearn/checkpoints/README.md: the joint-path TMs are 128-128-128 (train-planner's default widths),
    # the obstacle-aware TM was trained with the command's learning rate, now the config's too.
    assert PLANNER_MODEL["hidden"] == (128, 128, 128)
    assert ObstacleTrainConfig.lr == 2e-3
    tm = load_checkpoint(DEFAULT_CHECKPOINTS / "iiwa14" / "tm.pt", kind=None)
    assert tuple(tm["config"]["hidden"]) == PLANNER_MODEL["hidden"]


def test_the_babbling_step_is_one_constant_and_an_older_fm_reads_it():
    assert BabblingConfig.max_step == FMConfig.max_step == PathTrainConfig.max_step == MAX_STEP
    shipped = load_checkpoint(DEFAULT_CHECKPOINTS / "iiwa14" / "fm.pt", kind="fm")
    assert "max_step" not in shipped["config"]  # made before the FM recorded it
    planner = Planner.default("iiwa14")
    assert planner.fm.max_step == planner.max_step == MAX_STEP
    assert AnalyticFM("iiwa14").max_step == MAX_STEP
    # at the default the record is what it was: no new key in configs or checkpoints
    assert "max_step" not in fm_config("iiwa14", "tiny").to_dict()


def test_an_fm_records_its_datas_step_and_the_planner_bounds_actions_by_it(tmp_path):
    data = babble(BabblingConfig(walkers=40, steps=10, max_step=0.05, seed=3))
    result = train_fm(
        data,
        fm_config("iiwa14", "tiny"),
        train_config("fm", "tiny", epochs=1, progress=False),
        run_dir=tmp_path,
    )
    assert result.model.max_step == 0.05
    fm = load_fm(tmp_path / "fm.pt")
    assert fm.max_step == 0.05 and fm.config.max_step == 0.05
    shipped = Planner.default("iiwa14")
    planner = Planner(shipped.robot, shipped.tm, fm, shipped.im)
    assert planner.max_step == 0.05
    assert Planner(shipped.robot, shipped.tm, fm, shipped.im, max_step=0.02).max_step == 0.02
    with pytest.raises(ConfigError, match="max_step"):
        FMConfig(max_step=0.0)
