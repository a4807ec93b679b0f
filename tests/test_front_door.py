"""The public API: a small front door (``kinlearn.__all__``), every name documented in docs/usage.md,
the rest in modules named for their purpose, the old names still resolving with a warning that names
their new home, every error reachable, and ``kinlearn.load`` for any file kinlearn writes."""

from __future__ import annotations

import importlib
import re
import subprocess
import sys
from pathlib import Path

import pytest
import torch

import kinlearn
import kinlearn.errors as errors
from kinlearn.body.robot import load_robot
from kinlearn.data.endpoints import EndpointConfig, make_endpoints
from kinlearn.errors import CheckpointError
from kinlearn.io import save_checkpoint

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "kinlearn" / "checkpoints" / "iiwa14"
#: The modules a user finds the rest in, by purpose.
HOMES = ("train", "baselines", "models", "data", "collision", "body", "errors")


def test_the_front_door_is_small_and_documented():
    assert len(kinlearn.__all__) <= 30 and len(set(kinlearn.__all__)) == len(kinlearn.__all__)
    usage = (ROOT / "docs" / "usage.md").read_text(encoding="utf-8")
    undocumented = [
        n for n in kinlearn.__all__ if not re.search(rf"`(kinlearn\.)?{re.escape(n)}[`(.]", usage)
    ]
    assert not undocumented, f"not in docs/usage.md: {undocumented}"
    for home in HOMES:  # every home is named there too
        assert f"kinlearn.{home}" in usage, home


def test_every_error_is_documented_and_the_common_ones_are_at_the_front_door():
    classes = {
        n: c
        for n, c in vars(errors).items()
        if isinstance(c, type) and issubclass(c, (Exception, Warning)) and c.__module__ == errors.__name__
    }
    assert len(classes) >= 25
    for name, cls in classes.items():
        assert cls.__doc__ and len(cls.__doc__) > 20, name
        assert issubclass(cls, Warning) or issubclass(cls, kinlearn.KinlearnError), name
    front = [n for n in kinlearn.__all__ if n in classes]
    assert {"KinlearnError", "ObstacleError", "TimingError", "TrainingDivergedError"} <= set(front)
    for name in front:
        assert getattr(kinlearn, name) is classes[name]
    # one left at kinlearn.errors is caught by a front-door error it derives from, or by KinlearnError
    assert issubclass(errors.DTypeError, kinlearn.ShapeError) and issubclass(
        errors.SceneFormatError, kinlearn.ObstacleError
    )


def test_the_homes_by_purpose_resolve_every_name():
    for home in HOMES:
        module = importlib.import_module(f"kinlearn.{home}")
        names = getattr(module, "__all__", None)
        if names is None:  # kinlearn.errors: its classes
            continue
        for name in names:
            assert getattr(module, name) is not None, f"kinlearn.{home}.{name}"
        assert set(names) <= set(dir(module)), home
    assert kinlearn.train.train_fm.__module__ == "kinlearn.training.forward_inverse"
    assert kinlearn.models.ChainFM.__module__ == "kinlearn.models.chain"


def test_the_old_names_still_resolve_and_say_where_they_went():
    assert len(kinlearn.MOVED) >= 70 and not set(kinlearn.MOVED) & set(kinlearn.__all__)
    for old, new in kinlearn.MOVED.items():
        home, _, attr = new.rpartition(".")
        with pytest.warns(DeprecationWarning, match=re.escape(new)):
            value = getattr(kinlearn, old)
        assert value is getattr(importlib.import_module(home), attr), old
    with pytest.warns(DeprecationWarning, match="kinlearn.baselines.JointLine"):
        from kinlearn import JointInterpolation  # noqa: F401  (the from-import form too)


def test_the_homes_load_lazily():
    code = (
        "import sys, kinlearn.train, kinlearn.models, kinlearn.data, kinlearn.body\n"
        "print('torch' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False"]


# --------------------------------------------------------------------------------------------------
# kinlearn.load
# --------------------------------------------------------------------------------------------------


def test_load_dispatches_on_what_a_file_holds():
    from kinlearn.models import JointPathModel, LearnedBody, LearnedFM, LearnedIM, ObstaclePathModel
    from kinlearn.train import Identification

    planner = kinlearn.load(SHIPPED)
    assert isinstance(planner, kinlearn.Planner) and planner.robot.name == "iiwa14"
    for name, cls in (
        ("fm.pt", LearnedFM),
        ("im.pt", LearnedIM),
        ("tm.pt", JointPathModel),
        ("tm_obstacles.pt", ObstaclePathModel),
        ("body.pt", LearnedBody),
        ("chain.pt", Identification),  # an identification's chain comes with its report
    ):
        assert isinstance(kinlearn.load(SHIPPED / name), cls), name
    assert not kinlearn.load(SHIPPED / "fm.pt").training  # ready to use
    with pytest.raises(CheckpointError, match="not 'panda'"):
        kinlearn.load(SHIPPED / "fm.pt", robot="panda")


def test_load_reads_runs_and_their_checkpoints(tmp_path):
    from kinlearn.models import AnalyticFM, ChainFM, TrajectoryModel, save_model
    from kinlearn.train import Identification, tm_preset, train_tm
    from kinlearn.training.imitation import train_imitation

    robot = load_robot("iiwa14")
    pairs = make_endpoints(EndpointConfig(n=8, seed=1))
    cfg = tm_preset("default", fm="analytic", im="analytic", epochs=1, batch_size=8)
    train_tm(cfg, tmp_path / "run", pairs, progress=False)
    assert isinstance(kinlearn.load(tmp_path / "run"), kinlearn.Planner)  # a run directory
    assert isinstance(kinlearn.load(tmp_path / "run" / "tm.pt"), TrajectoryModel)  # the paper's TM
    train_imitation(pairs, epochs=1, batch_size=8, progress=False, run_dir=tmp_path / "imitation")
    assert isinstance(kinlearn.load(tmp_path / "imitation" / "imitation.pt"), TrajectoryModel)
    save_model(AnalyticFM(robot), tmp_path / "analytic.pt")
    assert isinstance(kinlearn.load(tmp_path / "analytic.pt"), AnalyticFM)
    chain = ChainFM.from_robot(robot)
    save_model(chain, tmp_path / "bare" / "chain.pt")  # a chain without an identification's report
    assert type(kinlearn.load(tmp_path / "bare" / "chain.pt")) is ChainFM
    Identification(chain, {"heldout": {"median_m": 0.0}}).save(tmp_path / "identify" / "chain.pt")
    loaded = kinlearn.load(tmp_path / "identify")  # an identify run directory
    assert isinstance(loaded, Identification) and torch.equal(loaded.model.axis, chain.axis)


def test_load_refuses_what_it_does_not_know(tmp_path):
    with pytest.raises(CheckpointError, match="no checkpoint file or run directory"):
        kinlearn.load(tmp_path / "nothing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(CheckpointError, match="no planner"):
        kinlearn.load(tmp_path / "empty")
    (tmp_path / "notes.pt").write_text("not a checkpoint")
    with pytest.raises(CheckpointError, match="not a readable kinlearn checkpoint"):
        kinlearn.load(tmp_path / "notes.pt")
    save_checkpoint(tmp_path / "odd.pt", kind="odd", robot="iiwa14", config={}, state_dict={})
    with pytest.raises(CheckpointError, match=r"kind 'odd'.*known kinds: fm, im"):
        kinlearn.load(tmp_path / "odd.pt")
    with pytest.raises(CheckpointError, match=r"odd\.pt"):  # a folder of other checkpoints names them
        kinlearn.load(tmp_path)


def test_the_front_doors_imports_are_its_all():
    """What ``kinlearn/__init__.py`` imports (the errors, and the lazy table under ``TYPE_CHECKING``) is
    ``__all__`` and nothing else, so the list a reader sees and the names that resolve are one."""
    import ast

    tree = ast.parse((ROOT / "kinlearn" / "__init__.py").read_text(encoding="utf-8"))
    imported = {
        alias.asname or alias.name
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 1 and node.module != "lazy"
        for alias in node.names
    }
    assert imported | {"__version__"} == set(kinlearn.__all__)
    for name in kinlearn.__all__:
        assert name in dir(kinlearn) and getattr(kinlearn, name) is not None, name
    assert issubclass(kinlearn.KinlearnWarning, UserWarning) and "KinlearnWarning" in kinlearn.__all__
