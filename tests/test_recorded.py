"""Recorded logs (.npz/.csv): round trips, joint matching, every bad file's typed error, transitions for
the trainers, and the one ``--data`` loader."""

import json
import math

import numpy as np
import pytest
import torch

from kinlearn import load_robot
from kinlearn.cli.main import main
from kinlearn.data.babbling import BabblingConfig, Transitions, babble, load_transitions, save_transitions
from kinlearn.data.recorded import Observations, load_data, load_recorded, save_recorded
from kinlearn.errors import DatasetError, RecordedDataError
from kinlearn.io import file_sha256, save_npz
from kinlearn.models.forward_inverse import fm_config
from kinlearn.train import train_fm
from kinlearn.training.forward_inverse import train_config

ROBOT = load_robot("iiwa14")


@pytest.fixture(scope="module")
def babbled() -> Transitions:
    return babble(BabblingConfig(walkers=3, steps=20, seed=2, dtype="float64"))


@pytest.fixture
def obs(babbled) -> Observations:
    o = Observations.from_transitions(babbled, ROBOT.joint_names)
    return Observations(o.theta, o.ef, o.episode, 0.01 * torch.arange(len(o)), o.joint_names)


def rows_of(t: Transitions) -> list[tuple]:
    return sorted(map(tuple, torch.cat((t.s, t.a, t.s_next), 1).tolist()))


def write_csv(path, header, rows):
    path.write_text(",".join(header) + "\n" + "".join(",".join(map(str, r)) + "\n" for r in rows))
    return path


def csv_rows(o: Observations, n: int | None = None) -> list[list]:
    """Rows [θ..., ef_x, ef_y, ef_z] of observations, as Python floats."""
    return torch.cat((o.theta, o.ef), 1)[:n].tolist()


HEADER = [*ROBOT.joint_names, "ef_x", "ef_y", "ef_z"]


# --------------------------------------------------------------------------------------------------
# Round trips and transitions
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("suffix", ["npz", "csv"])
def test_round_trip_is_exact(tmp_path, obs, suffix):
    path = save_recorded(tmp_path / f"log.{suffix}", obs)
    back = load_recorded(path, robot="iiwa14")
    assert torch.equal(back.theta, obs.theta) and torch.equal(back.ef, obs.ef)
    assert torch.equal(back.episode, obs.episode) and torch.equal(back.time, obs.time)
    assert back.theta.dtype == back.ef.dtype == torch.float64 and back.episode.dtype == torch.int64
    assert back.joint_names == ROBOT.joint_names and back.dropped == 0
    assert back.path == path and back.sha256 == file_sha256(path)
    assert not list(tmp_path.glob(".*.tmp"))  # written atomically


def test_states_of_babbling_give_its_transitions_back(tmp_path, babbled):
    o = Observations.from_transitions(babbled, ROBOT.joint_names)
    # Three walkers: three episodes of 21 states each (the walk's last s' included).
    assert len(o) == 3 * 21 and o.episodes == 3
    assert torch.equal(o.episode, torch.arange(3).repeat_interleave(21))
    t = o.transitions("iiwa14")
    assert t.robot == "iiwa14" and len(t) == len(babbled)
    assert rows_of(t) == rows_of(babbled)
    # Through a file and the one loader, with the trainers' data type.
    back = load_data(save_recorded(tmp_path / "log.csv", o), robot="iiwa14")
    assert isinstance(back, Transitions) and rows_of(back) == rows_of(babbled)
    assert back.config["source"] == "recorded" and back.config["transitions"] == len(babbled)


def test_transitions_are_consecutive_rows_within_episodes():
    theta = torch.tensor([[0.0], [0.1], [0.3], [1.0], [1.5]], dtype=torch.float64)
    ef = torch.zeros(5, 3, dtype=torch.float64)
    o = Observations(theta, ef, torch.tensor([4, 4, 4, 9, 9]))
    t = o.transitions("arm")
    assert torch.allclose(t.a, torch.tensor([[0.1], [0.2], [0.5]], dtype=torch.float64), atol=1e-12)
    assert torch.equal(t.s[:, 0], torch.tensor([0.0, 0.1, 1.0], dtype=torch.float64))
    assert torch.equal(t.s_next[:, 0], torch.tensor([0.1, 0.3, 1.5], dtype=torch.float64))
    with pytest.raises(RecordedDataError, match=r"no transition"):
        Observations(theta, ef, torch.arange(5)).transitions("arm")


def test_episode_labels_are_renumbered_in_file_order(tmp_path, obs):
    rows = [[*r, e] for r, e in zip(csv_rows(obs, 6), (7, 7, 3, 3, 3, 12), strict=True)]
    back = load_recorded(write_csv(tmp_path / "e.csv", [*HEADER, "episode"], rows))
    assert back.episode.tolist() == [0, 0, 1, 1, 1, 2] and back.episodes == 3


def test_csv_joint_columns_in_any_order_are_matched_to_the_robot(tmp_path, obs):
    order = [6, 2, 0, 5, 1, 4, 3]
    header = [ROBOT.joint_names[j] for j in order] + ["ef_z", "ef_x", "ef_y"]
    rows = [[r[j] for j in order] + [r[9], r[7], r[8]] for r in csv_rows(obs, 10)]
    path = write_csv(tmp_path / "shuffled.csv", header, rows)
    back = load_recorded(path, robot=ROBOT)
    assert back.joint_names == ROBOT.joint_names
    assert torch.equal(back.theta, obs.theta[:10]) and torch.equal(back.ef, obs.ef[:10])
    # Without a robot: the joints in file order, named as in the file.
    plain = load_recorded(path, dof=7)
    assert plain.joint_names == tuple(header[:7])
    assert torch.equal(plain.theta, obs.theta[:10, order])
    assert plain.time is None and plain.episode.tolist() == [0] * 10


def test_kinlearn_babbling_files_load_as_before(tmp_path, babbled):
    path = save_transitions(babbled, tmp_path / "babbling.npz")
    a, b = load_data(path, robot="iiwa14"), load_transitions(path, robot="iiwa14")
    assert all(torch.equal(x, y) for x, y in zip(a.tensors(), b.tensors(), strict=True))
    assert a.config == b.config
    with pytest.raises(DatasetError, match=r"panda"):
        load_data(path, robot="panda")


def test_the_trainers_learn_from_a_recorded_log(tmp_path, obs):
    data = load_data(save_recorded(tmp_path / "log.npz", obs), robot="iiwa14")
    res = train_fm(data, fm_config("iiwa14", "tiny"), train_config("fm", "tiny", epochs=1, progress=False))
    assert len(res.history) == 1 and math.isfinite(res.history[0]["train_loss"])


def test_train_fm_command_takes_a_recorded_log(tmp_path, obs, capsys):
    log = save_recorded(tmp_path / "log.csv", obs)
    run = tmp_path / "fm"
    argv = ["train-fm", "--preset", "tiny", "--data", str(log), "--epochs", "1", "--validate", "0"]
    assert main([*argv, "--no-progress", "--run-dir", str(run)]) == 0
    record = json.loads((run / "config.json").read_text())
    assert record["data"]["sha256"] == file_sha256(log)
    assert record["recorded"]["rows"] == len(obs) and record["recorded"]["source"] == "recorded"
    assert (run / "fm.pt").is_file()
    # A bad log is refused before anything is written.
    bad = write_csv(tmp_path / "bad.csv", HEADER, [[*csv_rows(obs, 1)[0][:-1], "x"]])
    assert main([*argv, "--data", str(bad), "--run-dir", str(tmp_path / "no")]) == 2
    assert "is not a number" in capsys.readouterr().err and not (tmp_path / "no").exists()


# --------------------------------------------------------------------------------------------------
# Bad files: typed errors that say what to fix
# --------------------------------------------------------------------------------------------------


def test_missing_empty_unreadable_and_unknown_files(tmp_path):
    with pytest.raises(RecordedDataError, match=r"no such file"):
        load_recorded(tmp_path / "none.csv")
    (tmp_path / "empty.csv").write_text("")
    with pytest.raises(RecordedDataError, match=r"empty"):
        load_recorded(tmp_path / "empty.csv")
    (tmp_path / "log.txt").write_text("a,b\n1,2\n")
    with pytest.raises(RecordedDataError, match=r"unknown suffix '\.txt'.*\.npz or a \.csv"):
        load_recorded(tmp_path / "log.txt")
    (tmp_path / "bad.npz").write_bytes(b"not a zip file")
    with pytest.raises(RecordedDataError, match=r"not a readable .npz"):
        load_recorded(tmp_path / "bad.npz")
    (tmp_path / "latin.csv").write_bytes(b"q\xe9,ef_x,ef_y,ef_z\n0,0,0,0\n")
    with pytest.raises(RecordedDataError, match=r"UTF-8"):
        load_recorded(tmp_path / "latin.csv")
    (tmp_path / "header.csv").write_text(",".join(HEADER) + "\n")
    with pytest.raises(RecordedDataError, match=r"no data rows"):
        load_recorded(tmp_path / "header.csv")
    (tmp_path / "noheader.csv").write_text("0.1,0.2,0.3,0.4\n0.1,0.2,0.3,0.4\n")
    with pytest.raises(RecordedDataError, match=r"header"):
        load_recorded(tmp_path / "noheader.csv")
    assert issubclass(RecordedDataError, DatasetError)


def test_missing_and_unknown_columns_and_keys(tmp_path, obs):
    rows = [r[:8] for r in csv_rows(obs, 3)]
    with pytest.raises(RecordedDataError, match=r"lacks the column.*ef_y, ef_z"):
        load_recorded(write_csv(tmp_path / "a.csv", HEADER[:8], rows))
    with pytest.raises(RecordedDataError, match=r"'Episode'.*named exactly"):
        load_recorded(
            write_csv(tmp_path / "b.csv", [*HEADER, "Episode"], [[*r, 0] for r in csv_rows(obs, 3)])
        )
    with pytest.raises(RecordedDataError, match=r"more than once"):
        load_recorded(write_csv(tmp_path / "c.csv", [*HEADER, "ef_x"], [[*r, 0] for r in csv_rows(obs, 3)]))
    np.savez(tmp_path / "d.npz", theta=obs.theta.numpy())
    with pytest.raises(RecordedDataError, match=r"lacks the key.*ef"):
        load_recorded(tmp_path / "d.npz")
    np.savez(tmp_path / "e.npz", theta=obs.theta.numpy(), ef=obs.ef.numpy(), episodes=obs.episode.numpy())
    with pytest.raises(RecordedDataError, match=r"unknown key.*episodes"):
        load_recorded(tmp_path / "e.npz")
    np.savez(tmp_path / "f.npz", theta=obs.theta.numpy(), ef=obs.ef.numpy()[:, :2])
    with pytest.raises(RecordedDataError, match=r"ef must have shape \(63, 3\)"):
        load_recorded(tmp_path / "f.npz")


def test_joint_columns_must_be_the_robots(tmp_path, obs):
    header = ["iiwa_joint_1", "elbow", *ROBOT.joint_names[2:], "ef_x", "ef_y", "ef_z"]
    path = write_csv(tmp_path / "names.csv", header, csv_rows(obs, 3))
    with pytest.raises(RecordedDataError, match=r"'elbow' name no joint.*iiwa_joint_2 have no column"):
        load_recorded(path, robot="iiwa14")
    extra = write_csv(tmp_path / "extra.csv", ["force", *HEADER], [[0.0, *r] for r in csv_rows(obs, 3)])
    with pytest.raises(RecordedDataError, match=r"'force' name no joint"):
        load_recorded(extra, robot="iiwa14")
    npz = save_recorded(tmp_path / "named.npz", obs)
    with pytest.raises(RecordedDataError, match=r"name no joint of panda"):
        load_recorded(npz, robot="panda")


def test_wrong_dof(tmp_path, obs):
    np.savez(tmp_path / "six.npz", theta=obs.theta.numpy()[:, :6], ef=obs.ef.numpy())
    with pytest.raises(RecordedDataError, match=r"6 joint column.*iiwa14' has 7"):
        load_recorded(tmp_path / "six.npz", robot="iiwa14")
    with pytest.raises(RecordedDataError, match=r"6 joint column.*dof asks for 7"):
        load_recorded(tmp_path / "six.npz", dof=7)
    with pytest.raises(RecordedDataError, match=r"dof=6 was asked for"):
        load_recorded(tmp_path / "six.npz", robot="iiwa14", dof=6)
    assert load_recorded(tmp_path / "six.npz", dof=6).dof == 6


def test_non_numeric_cells_name_their_line_and_column(tmp_path, obs):
    rows = csv_rows(obs, 4)
    rows[2][8] = "0.1mm"
    with pytest.raises(RecordedDataError, match=r"line 4, column 'ef_y': '0.1mm' is not a number"):
        load_recorded(write_csv(tmp_path / "t.csv", HEADER, rows))
    rows = csv_rows(obs, 4)
    rows[1] = rows[1][:5]
    with pytest.raises(RecordedDataError, match=r"line 3 has 5 cells; the header names 10"):
        load_recorded(write_csv(tmp_path / "short.csv", HEADER, rows))
    np.savez(tmp_path / "b.npz", theta=obs.theta.numpy() > 0, ef=obs.ef.numpy())
    with pytest.raises(RecordedDataError, match=r"theta holds bool"):
        load_recorded(tmp_path / "b.npz")


def test_nan_rows_are_refused_or_dropped_with_a_count(tmp_path, obs):
    rows = csv_rows(obs)
    for i in (3, 10, 11):  # the second walk's rows 21+: keep the episode column plain
        rows[i][i % 10] = math.nan
    rows[30][7] = ""  # an empty cell is NaN too
    rows[40][8] = "inf"
    rows = [[*r, int(e)] for r, e in zip(rows, obs.episode.tolist(), strict=True)]
    path = write_csv(tmp_path / "nan.csv", [*HEADER, "episode"], rows)
    with pytest.raises(
        RecordedDataError, match=r"5 row\(s\) hold NaN or infinity \(lines 5, 12, 13, 32, 42\).*drop"
    ):
        load_recorded(path, robot="iiwa14")
    with pytest.warns(UserWarning, match=r"dropped 5 row\(s\)"):
        back = load_recorded(path, robot="iiwa14", drop_nan=True)
    assert back.dropped == 5 and len(back) == len(obs) - 5
    assert bool(torch.isfinite(back.theta).all() and torch.isfinite(back.ef).all())
    # A dropped row splits its episode: no transition spans it.
    t = back.transitions("iiwa14")
    assert len(t) == len(obs) - 3 - 5 - 4  # 3 episodes, 5 rows gone, 4 more breaks (10 and 11 are adjacent)
    assert float((t.s_next[:, :7] - t.s[:, :7] - t.a).abs().max()) == 0.0
    assert float(t.a.abs().max()) <= 0.083 + 1e-12  # only single babbling steps
    np.savez(tmp_path / "all.npz", theta=np.full((2, 7), np.nan), ef=np.zeros((2, 3)))
    with pytest.raises(RecordedDataError, match=r"every one of its 2 rows"):
        load_recorded(tmp_path / "all.npz", drop_nan=True)


def test_millimetres_are_recognised(tmp_path, obs):
    mm = Observations(obs.theta, obs.ef * 1000, obs.episode)
    path = save_recorded(tmp_path / "mm.npz", mm)
    for robot in (None, "iiwa14"):
        with pytest.raises(RecordedDataError, match=r"millimetres, divide by 1000"):
            load_recorded(path, robot=robot)
    # Four times the arm's reach: beyond 3 × the iiwa14's reach, within the 10 m of an unknown arm.
    four = save_recorded(tmp_path / "four.npz", Observations(obs.theta, obs.ef * 4, obs.episode))
    with pytest.raises(RecordedDataError, match=r"3 × the reach of iiwa14"):
        load_recorded(four, robot="iiwa14")
    assert len(load_recorded(four)) == len(obs)


def test_degrees_are_recognised(tmp_path, obs):
    path = save_recorded(tmp_path / "deg.npz", Observations(torch.rad2deg(obs.theta), obs.ef, obs.episode))
    for robot in (None, "iiwa14"):
        with pytest.raises(RecordedDataError, match=r"radians.*deg2rad"):
            load_recorded(path, robot=robot)


def test_joints_outside_the_limits_are_counted(tmp_path, obs):
    theta = obs.theta.clone()
    theta[[5, 9], 3] = float(ROBOT.upper[3]) + 0.2
    path = save_recorded(tmp_path / "out.npz", Observations(theta, obs.ef, obs.episode))
    with pytest.raises(
        RecordedDataError, match=r"2 row\(s\) hold joints outside iiwa14's limits \(rows \(from 0\) 5, 9"
    ):
        load_recorded(path, robot="iiwa14")
    assert len(load_recorded(path)) == len(obs)  # no robot: no limits to hold them to


def test_time_must_increase_within_an_episode(tmp_path, obs):
    time = obs.time.clone()
    time[21:] -= 1.0  # time may start again with each episode
    assert len(
        load_recorded(save_recorded(tmp_path / "ok.npz", Observations(obs.theta, obs.ef, obs.episode, time)))
    )
    time[[30, 50]] = time[[29, 49]]  # a repeated sample in each of two episodes
    path = save_recorded(tmp_path / "t.npz", Observations(obs.theta, obs.ef, obs.episode, time))
    with pytest.raises(
        RecordedDataError,
        match=r"time does not increase within an episode at 2 row\(s\) \(rows \(from 0\) 30, 50",
    ):
        load_recorded(path)


def test_episodes_must_be_consecutive_whole_numbers(tmp_path, obs):
    episode = obs.episode.clone()
    episode[5] = 2
    path = save_recorded(tmp_path / "split.npz", Observations(obs.theta, obs.ef, episode))
    with pytest.raises(RecordedDataError, match=r"rows of episode 0 are not consecutive"):
        load_recorded(path)
    np.savez(
        tmp_path / "frac.npz", theta=obs.theta.numpy(), ef=obs.ef.numpy(), episode=np.full(len(obs), 0.5)
    )
    with pytest.raises(RecordedDataError, match=r"not whole numbers"):
        load_recorded(tmp_path / "frac.npz")


def test_observations_check_their_shapes():
    from kinlearn import ShapeError

    with pytest.raises(ShapeError):
        Observations(torch.zeros(4, 7), torch.zeros(4, 2))
    with pytest.raises(ShapeError):
        Observations(torch.zeros(4, 7), torch.zeros(4, 3), torch.zeros(3))
    with pytest.raises(ShapeError):
        Observations(torch.zeros(4, 7), torch.zeros(4, 3), joint_names=("a", "b"))


def test_save_refuses_unknown_suffixes(tmp_path, obs):
    with pytest.raises(RecordedDataError, match=r"unknown suffix"):
        save_recorded(tmp_path / "log.json", obs)


def test_a_foreign_kinlearn_dataset_is_a_dataset_error(tmp_path):
    other = save_npz(tmp_path / "o.npz", kind="pairs", robot="iiwa14", config={}, arrays={"x": np.zeros(3)})
    with pytest.raises(DatasetError, match=r"pairs"):
        load_data(other)


def test_a_urdf_robots_log_and_babbling_load_for_that_robot(tmp_path):
    from kinlearn.evaluation.model_error import write_perturbed_urdf

    urdf = write_perturbed_urdf("iiwa14", tmp_path / "bent.urdf", seed=3)
    robot = load_robot(urdf, ee_frame="iiwa_link_ee")
    cfg = BabblingConfig(walkers=5, steps=8, urdf=str(urdf), ee_frame="iiwa_link_ee", ef_noise=0.001)
    babbled = babble(cfg)
    npz = save_transitions(babbled, tmp_path / "babbling.npz")
    assert rows_of(load_data(npz, robot=robot)) == rows_of(babbled)
    log = save_recorded(tmp_path / "log.csv", Observations.from_transitions(babbled, robot.joint_names))
    back = load_recorded(log, robot=robot)
    assert back.joint_names == robot.joint_names and len(back) == 5 * 9
    assert rows_of(load_data(log, robot=robot)) == rows_of(babbled.to(torch.float64))
