"""Recorded CSV logs read in chunks, never whole: every row checked across chunk boundaries as in one
piece (episodes, time, NaN gaps), and a seeded reservoir sample of ``max_rows`` rows whose memory is
bounded by that sample, not by the file."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
import torch

import kinlearn.data.recorded as recorded
from kinlearn.data.recorded import Observations, load_recorded, save_recorded
from kinlearn.errors import DroppedRowsWarning, RecordedDataError


def _log(n, dof=3, seed=0, episodes=7):
    rng = np.random.default_rng(seed)
    theta = rng.uniform(-2, 2, (n, dof))
    ef = rng.uniform(-0.5, 0.5, (n, 3))
    episode = np.sort(rng.integers(0, episodes, n))
    time = np.arange(n) * 0.01
    return Observations(theta, ef, episode, time)


def _same(a: Observations, b: Observations) -> None:
    for key in ("theta", "ef", "episode", "time"):
        assert torch.equal(getattr(a, key), getattr(b, key)), key
    assert a.dropped == b.dropped


def test_chunks_read_as_the_file_in_one_piece(tmp_path, monkeypatch):
    obs = _log(2500)
    obs.theta[[999, 1000, 1700], 1] = float("nan")  # dropped rows at and beside a chunk boundary
    path = save_recorded(tmp_path / "log.csv", obs)
    with pytest.warns(DroppedRowsWarning, match=r"dropped 3 row\(s\) .*\(lines 1001, 1002, 1702\)"):
        whole = load_recorded(path, drop_nan=True)
    monkeypatch.setattr(recorded, "CSV_CHUNK_ROWS", 1000)
    with pytest.warns(DroppedRowsWarning, match=r"dropped 3 row\(s\) .*\(lines 1001, 1002, 1702\)"):
        chunked = load_recorded(path, drop_nan=True)
    _same(whole, chunked)
    assert len(chunked) == 2497 and chunked.episodes > 7  # the gaps end their episodes' runs


@pytest.mark.parametrize(
    "change, match",
    [
        (
            lambda o: o.episode.__setitem__(slice(2000, 2010), 0),
            r"rows of episode 0 are not consecutive.*line 2002",
        ),
        (
            lambda o: o.time.__setitem__(1000, 0.0),
            r"time does not increase within an episode at 1 row\(s\) \(line 1002\)",
        ),
        (lambda o: o.ef.__setitem__((2200, 0), 5000.0), r"line 2202.*millimetres"),
        (
            lambda o: o.theta.__setitem__((2300, 2), float("nan")),
            r"1 row\(s\) hold NaN or infinity \(line 2302\)",
        ),
    ],
)
def test_errors_beyond_the_first_chunk_name_their_line(tmp_path, monkeypatch, change, match):
    obs = _log(2500, episodes=3)
    change(obs)
    path = save_recorded(tmp_path / "log.csv", obs)
    monkeypatch.setattr(recorded, "CSV_CHUNK_ROWS", 1000)
    with pytest.raises(RecordedDataError, match=match):
        load_recorded(path)


def test_a_reservoir_sample_is_seeded_uniform_and_of_the_files_rows(tmp_path, monkeypatch):
    obs = _log(5000)
    obs.theta[:, 0] = torch.arange(5000, dtype=torch.float64) * 1e-4  # each row's index, readable back
    path = save_recorded(tmp_path / "log.csv", obs)
    monkeypatch.setattr(recorded, "CSV_CHUNK_ROWS", 700)
    a = load_recorded(path, max_rows=400, seed=3)
    b = load_recorded(path, max_rows=400, seed=3)
    c = load_recorded(path, max_rows=400, seed=4)
    assert torch.equal(a.theta, b.theta) and not torch.equal(a.theta, c.theta)
    index = torch.round(a.theta[:, 0] * 1e4).long()
    assert len(a) == 400 and a.sampled_from == 5000 and len(set(index.tolist())) == 400
    torch.testing.assert_close(a.theta, obs.theta[index])
    torch.testing.assert_close(a.ef, obs.ef[index])
    # uniform over the file: each fifth of it holds about a fifth of the sample
    counts = np.bincount(index.numpy() // 1000, minlength=5)
    assert counts.min() > 50 and counts.max() < 110
    assert a.time is None and a.episodes == 400  # no transitions across a sample's rows
    assert len(load_recorded(path, max_rows=9000)) == 5000


def test_memory_is_bounded_by_the_sample_not_the_file(tmp_path, monkeypatch):
    """A 100,000-row log (about 10 MB of text) read into a 500-row sample in chunks of 2,000 rows: the
    peak of Python's and NumPy's allocations stays near one chunk, far below the file."""
    n = 100_000
    rng = np.random.default_rng(1)
    table = np.column_stack((rng.uniform(-2, 2, (n, 7)), rng.uniform(-0.5, 0.5, (n, 3))))
    path = tmp_path / "big.csv"
    names = [f"j{i}" for i in range(7)] + ["ef_x", "ef_y", "ef_z"]
    np.savetxt(path, table, fmt="%.17g", delimiter=",", header=",".join(names), comments="")
    size = path.stat().st_size
    assert size > 8e6
    monkeypatch.setattr(recorded, "CSV_CHUNK_ROWS", 2000)
    tracemalloc.start()
    try:
        obs = load_recorded(path, max_rows=500, seed=0)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert len(obs) == 500 and obs.sampled_from == n
    assert peak < size / 8, (peak, size)
