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


def test_kinlearn_help_answers_without_torch():
    code = (
        "import sys\n"
        "from kinlearn.cli.main import main\n"
        "try:\n"
        "    main(['--help'])\n"
        "except SystemExit as exc:\n"
        "    assert exc.code == 0\n"
        "print('torch' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "train-planner" in out and out.split()[-1] == "False"


def test_the_light_help_is_the_full_parsers():
    """`kinlearn --help` comes from a table (COMMANDS) so as not to import the commands: it must list what
    the full parser holds, in its order, with the same help (add a new command to COMMANDS too)."""
    from kinlearn.body.robot import BUILTIN_ROBOTS
    from kinlearn.cli.common import OWN_ROBOTS
    from kinlearn.cli.main import _top_level_parser, build_parser

    assert _top_level_parser().format_help() == build_parser().format_help()
    assert set(OWN_ROBOTS) == set(BUILTIN_ROBOTS)


def test_command_order_does_not_depend_on_what_was_imported_first():
    """A stage's CLI module imported before the parser is built (as a test or a script may) keeps
    ``--help``'s order: the full parser orders commands by module, not by import order."""
    import subprocess
    import sys

    code = (
        "import kinlearn.cli.evaluate, kinlearn.cli.export\n"
        "from kinlearn.cli.main import _top_level_parser, build_parser\n"
        "assert _top_level_parser().format_help() == build_parser().format_help()\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
