"""`import kinlearn` is cheap: the public names are imported when first used, torch with them."""

from __future__ import annotations

import subprocess
import sys

import kinlearn


def test_every_public_name_resolves():
    for name in kinlearn.__all__:
        assert getattr(kinlearn, name) is not None, name
    assert kinlearn.collision.Scene is kinlearn.Scene  # sub-packages too
    assert set(kinlearn.__all__) <= set(dir(kinlearn))


def test_an_unknown_name_is_an_attribute_error():
    import pytest

    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        kinlearn.nope  # noqa: B018


def test_import_kinlearn_loads_no_torch():
    code = "import sys, kinlearn; print('torch' in sys.modules, 'numpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "False"]
