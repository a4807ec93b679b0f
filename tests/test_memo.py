"""kinlearn.memo: results kept on disk between processes, keyed by everything they depend on."""

import numpy as np
import pytest

from kinlearn import memo


@pytest.fixture
def folder(tmp_path, monkeypatch):
    monkeypatch.setenv("KINLEARN_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path / "cache"


def counted(value):
    calls = []

    def compute():
        calls.append(1)
        return value

    return compute, calls


def test_computed_once_then_read(folder):
    compute, calls = counted(np.arange(4.0))
    a = memo.remembered("t", (np.ones(3), 5, "x", b"bytes"), compute, dtype=np.float64, shape=(4,))
    b = memo.remembered("t", (np.ones(3), 5, "x", b"bytes"), compute, dtype=np.float64, shape=(4,))
    assert len(calls) == 1 and np.array_equal(a, b) and not b.flags.writeable
    assert len(list(folder.iterdir())) == 1


def test_every_part_is_in_the_key(folder, tmp_path):
    compute, calls = counted(np.zeros(2, dtype=bool))
    src = tmp_path / "code.py"
    src.write_text("x = 1\n")
    base = ((np.ones(3), 5), ())
    for parts, code in (
        base,
        ((np.ones(3) * 2, 5), ()),
        ((np.ones(3), 6), ()),
        ((np.ones(3, np.float32), 5), ()),
    ):
        memo.remembered("t", parts, compute, dtype=bool, shape=(2,), code=code)
    memo.remembered("t", base[0], compute, dtype=bool, shape=(2,), code=(str(src),))
    memo._SOURCES.clear()
    src.write_text("x = 2\n")  # the computation's code changed: a new key
    memo.remembered("t", base[0], compute, dtype=bool, shape=(2,), code=(str(src),))
    assert len(calls) == 6


def test_a_damaged_file_is_recomputed(folder):
    compute, calls = counted(np.arange(3.0))
    memo.remembered("t", (1,), compute, dtype=np.float64, shape=(3,))
    (path,) = folder.iterdir()
    path.write_bytes(b"not an array")
    out = memo.remembered("t", (1,), compute, dtype=np.float64, shape=(3,))
    assert len(calls) == 2 and np.array_equal(out, np.arange(3.0))
    assert np.array_equal(np.load(path), np.arange(3.0))  # rewritten whole


def test_a_wrong_shape_is_refused_not_cached(folder):
    with pytest.raises(ValueError, match="expected"):
        memo.remembered("t", (1,), lambda: np.zeros(2), dtype=np.float64, shape=(3,))
    assert not folder.exists() or not list(folder.iterdir())


def test_off_and_unwritable(tmp_path, monkeypatch):
    monkeypatch.setenv("KINLEARN_CACHE_DIR", "off")
    assert memo.cache_dir() is None
    compute, calls = counted(np.ones(1))
    memo.remembered("t", (), compute, dtype=np.float64, shape=(1,))
    memo.remembered("t", (), compute, dtype=np.float64, shape=(1,))
    assert len(calls) == 2
    blocker = tmp_path / "file"
    blocker.write_text("a file where the folder should be")
    monkeypatch.setenv("KINLEARN_CACHE_DIR", str(blocker / "cache"))
    assert np.array_equal(memo.remembered("t", (), compute, dtype=np.float64, shape=(1,)), np.ones(1))


def test_the_body_proofs_read_back_equal(folder):
    """The pairs proven apart and the overlap shares: computed, then read back from disk by a fresh lookup
    (the process's own memory of them emptied), equal to a fresh computation."""
    from kinlearn.body.robot import load_robot
    from kinlearn.collision import kernel_body
    from kinlearn.collision.body import _default_pairs, always_overlapping, body_spheres

    robot = load_robot("panda")
    body = body_spheres(robot).double()
    kb = kernel_body.KernelBody(body)
    first = kernel_body.proven_apart(kb)
    kernel_body._APART.clear()
    again = kernel_body.proven_apart(kb)
    assert first.any() and np.array_equal(first, again)
    assert np.array_equal(again, kernel_body._prove(kb, *kb.box))
    link = body.link.numpy()
    spheres = np.column_stack((link, body.local.numpy(), body.radii.numpy()))
    pairs = _default_pairs(link.astype(np.int64))
    kept, share = always_overlapping(robot, spheres, pairs, samples=200)
    kept2, share2 = always_overlapping(robot, spheres, pairs, samples=200)
    assert np.array_equal(kept, kept2) and np.array_equal(share, share2)
    assert {p.name.split("-")[0] for p in folder.iterdir()} == {"overlap", "pairs"}
