"""Every Python and shell block of README.md and docs/*.md runs here, so that a drifted example fails.

One test per file; its blocks run in order in a temporary directory (as a reader at a clone's root:
``benchmarks/``, ``examples/``, ``robots/`` and ``kinlearn/checkpoints/`` are linked in), and blocks of one file may
build on each other:

- ````python```: one namespace per file.
- ````bash```: read command by command (``\\`` continues a line, ``#`` starts a comment, ``&&`` chains).
  ``kinlearn …`` runs in this process (:func:`kinlearn.cli.main.main`) and must exit 0 (``plan`` may exit
  1: a plan that missed its goal, as tiny models do); ``python - <<'EOF'`` runs its text as Python. What
  takes minutes or would change the installation (:data:`PARSE_ONLY`: ``kinlearn reproduce``,
  ``kinlearn model-error``, ``kinlearn export --to-package``, every ``python benchmarks/*.py``) is parsed
  by its own argument parser instead, so a renamed option or script still fails (``VAR=value`` before a
  command is dropped: ``OMP_NUM_THREADS=1 python benchmarks/…``); a synopsis
  (``[--option VALUE]``) must name only options its parser has. Set-up commands are checked: ``pip
  install -e '.[extra]'`` against pyproject.toml's extras, the test command against ``.ci/run``.
  Any other command fails: say here how to run it.
- ````text``` (``json``, ``yaml``, …): output or file contents, not run. A block without an info string fails.

Tiny sizes: the docs show real ones; :data:`TINY_OPTIONS` sets the amounts of work of the commands,
:data:`TINY_DEFAULTS` lowers configuration defaults, :data:`TINY_PYTHON` replaces literal text of a
file's Python (each entry must still match, so that this table keeps up with the docs). Every file a
block reads is one a clone holds (``examples/data/``: a recorded log, a URDF, a MoveIt scene and request):
no placeholder file is made for the docs.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import re
import runpy
import shlex
import sys
import types
import warnings
from dataclasses import dataclass
from pathlib import Path

import pytest
import torch

import kinlearn
from kinlearn.body import robot as robot_module
from kinlearn.data.babbling import BabblingConfig
from kinlearn.training.identify import IdentifyConfig

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
RUN = {"python": "python", "bash": "shell", "sh": "shell", "shell": "shell"}
NOT_RUN = {"text", "json", "yaml", "csv", "xml", "toml", "console", "output"}

#: Options set on each command, whatever the docs give (absent ones are added): the work of a real run,
#: cut to seconds. A command not listed runs as written.
TINY_OPTIONS: dict[str, dict[str, list[str]]] = {
    "babble": {"--transitions": ["3000"], "--walkers": ["50"]},
    "train-fm": {"--epochs": ["1"], "--validate": ["0"], "--no-progress": []},
    "train-im": {"--epochs": ["1"], "--through-fm-epochs": ["1"], "--validate": ["0"], "--no-progress": []},
    "train-planner": {"--iterations": ["2"], "--batch-size": ["16"], "--heldout": ["0"], "--no-progress": []},
    "make-endpoints": {"--n": ["64"], "--heldout": ["16"]},
    "train-tm": {"--epochs": ["1"], "--no-progress": []},
    "train-obstacle-planner": {
        "--problems-per-family": ["1"],
        "--iterations": ["2"],
        "--batch-size": ["2"],
        "--no-progress": [],
    },
    "validate": {"--n": ["1000"]},
    "identify": {"--quiet": []},
}

#: Defaults of configuration classes lowered while the docs run (the CLI has no option for them).
TINY_DEFAULTS = {
    IdentifyConfig: {"mlp_steps": 40, "mlp_hidden": (32, 32), "references": 1, "iterations": 4},
    BabblingConfig: {"walkers": 50, "steps": 40},
}

#: Literal replacements in a file's Python, (text, tiny text); each must occur in that file.
TINY_PYTHON: dict[str, list[tuple[str, str]]] = {
    "docs/training.md": [
        ("EndpointConfig(n=2000, seed=0)", "EndpointConfig(n=200, seed=0)"),
        (".split(1500)", ".split(150)"),
        ("epochs=10)", "epochs=1)"),
    ],
    "docs/planning.md": [
        ("plan.timed(dt=1 / 20)", "plan.timed(dt=1 / 4)"),
    ],
    "docs/baselines.md": [
        (
            'model_error_sweep("iiwa14", n_goals=2000, seeds=(0, 1, 2), progress=True)',
            'model_error_sweep("iiwa14", n_goals=8, seeds=(0,), levels=((0.02, 1.0),), calibration_samples=1000)',
        ),
    ],
}

#: Per file: text substituted in its commands (placeholders that stand for a value).
PLACEHOLDERS = {"docs/arms.md": {"NAME": "iiwa14"}}

#: Commands that run only their argument parser: (program, first word or None for every one).
PARSE_ONLY = {
    ("kinlearn", "reproduce"),
    ("kinlearn", "model-error"),
    ("kinlearn", "--to-package"),
    ("python", None),
}

#: Per file: commands run before its blocks (outputs of runs the file reads).
PREREQUISITES: dict[str, list[str]] = {}

#: Per file: names a block leaves to the reader (their own arrays), defined before the file's blocks.
READER_NAMES = {
    "docs/planning.md": """
import torch as _torch
_robot = kinlearn.load_robot("iiwa14")
start_joints, goal_joints = _robot.sample(2, _torch.Generator().manual_seed(0), dtype=_torch.float64)
my_joint_paths = _torch.stack([start_joints + (goal_joints - start_joints) * t for t in _torch.linspace(0, 1, 12)])
""",
}


@dataclass
class Block:
    doc: str  # path relative to the repository
    line: int  # of the opening fence
    info: str
    text: str


def blocks(path: Path) -> list[Block]:
    rel = path.relative_to(ROOT).as_posix()
    out, lines, i = [], path.read_text().splitlines(), 0
    while i < len(lines):
        m = re.match(r"^(\s*)(```+)(.*)$", lines[i])
        if not m:
            i += 1
            continue
        indent, fence, info = len(m.group(1)), m.group(2), m.group(3).strip()
        j = i + 1
        while j < len(lines) and not lines[j].strip().startswith(fence):
            j += 1
        assert j < len(lines), f"{rel}:{i + 1}: a code block that is never closed"
        text = "\n".join(line[indent:] for line in lines[i + 1 : j])
        out.append(Block(rel, i + 1, info.split()[0].lower() if info else "", text))
        i = j + 1
    return out


ALL_BLOCKS = [b for doc in DOCS for b in blocks(doc)]


def test_every_block_says_what_it_is():
    """A command to run is ```python or ```bash; output and file contents ```text (or json, yaml …)."""
    assert len(ALL_BLOCKS) > 40
    unknown = [
        f"{b.doc}:{b.line} ```{b.info}" for b in ALL_BLOCKS if b.info not in RUN and b.info not in NOT_RUN
    ]
    assert not unknown, "blocks without a known info string: " + ", ".join(unknown)


def test_tiny_python_still_matches():
    for doc, pairs in TINY_PYTHON.items():
        text = "\n".join(b.text for b in ALL_BLOCKS if b.doc == doc and RUN.get(b.info) == "python")
        for old, _ in pairs:
            assert old in text, f"TINY_PYTHON[{doc!r}]: {old!r} is no longer in its Python blocks"


# --------------------------------------------------------------------------------------------------
# Running a file's blocks
# --------------------------------------------------------------------------------------------------


class DocRun:
    def __init__(self, doc: str):
        self.doc = doc
        # A module of its own, so that a block may define dataclasses (they look their module up).
        self.module = types.ModuleType("kinlearn_docs_" + re.sub(r"\W", "_", doc))
        sys.modules[self.module.__name__] = self.module
        self.ns: dict = self.module.__dict__
        self.where = doc

    def fail(self, message: str):
        pytest.fail(f"{self.where}: {message}", pytrace=False)

    # ----------------------------------------------------------------------------------------- python
    def python(self, text: str, line: int, tiny: bool = True) -> None:
        if tiny:
            for old, new in TINY_PYTHON.get(self.doc, []):
                text = text.replace(old, new)
        code = compile("\n" * line + text, self.doc, "exec")  # tracebacks name the doc's lines
        exec(code, self.ns)

    # ------------------------------------------------------------------------------------------ shell
    def shell(self, text: str, line: int) -> None:
        lines = text.splitlines()
        i = 0
        while i < len(lines):
            start = i
            command = lines[i]
            while command.rstrip().endswith("\\") and i + 1 < len(lines):
                i += 1
                command = command.rstrip()[:-1] + " " + lines[i]
            i += 1
            here = re.search(r"<<\s*'?(\w+)'?\s*$", command)
            self.where = f"{self.doc}:{line + 1 + start}"
            if here:
                body = []
                while i < len(lines) and lines[i].strip() != here.group(1):
                    body.append(lines[i])
                    i += 1
                i += 1
                tokens = shlex.split(command[: here.start()], comments=True)
                if tokens[:2] not in (["python", "-"], ["python3", "-"]):
                    self.fail(f"a here-document for {tokens!r}: only `python -` is run")
                self.python("\n".join(body), line + 1 + start, tiny=False)
                continue
            tokens = shlex.split(command, comments=True)
            for sub in PLACEHOLDERS.get(self.doc, {}).items():
                tokens = [t.replace(*sub) for t in tokens]
            while tokens:
                cut = tokens.index("&&") if "&&" in tokens else len(tokens)
                self.command(tokens[:cut])
                tokens = tokens[cut + 1 :]

    def command(self, tokens: list[str]) -> None:
        while tokens and re.fullmatch(r"[A-Z_][A-Z0-9_]*=\S*", tokens[0]):  # VAR=value before a command
            tokens = tokens[1:]
        program, args = tokens[0], tokens[1:]
        if program == "kinlearn":
            self.kinlearn(args)
        elif program in ("python", "python3") and args[:2] == ["-m", "venv"]:
            pass  # a fresh environment: the suite runs in one
        elif program == "." and args == [".venv/bin/activate"]:
            pass
        elif program == "pip" and args[:1] == ["install"]:
            toml = (ROOT / "pyproject.toml").read_text()
            section = toml.split("[project.optional-dependencies]", 1)[1].split("\n[", 1)[0]
            extras = set(re.findall(r"^([\w-]+)\s*=", section, re.M))
            for arg in args[1:]:
                m = re.fullmatch(r"(?:\.|kinlearn)\[([\w,-]+)\]", arg)
                if m:
                    missing = set(m.group(1).split(",")) - extras
                    assert not missing, (
                        f"{self.where}: pip install {arg}: no extra {missing} in pyproject.toml"
                    )
        elif program in ("python", "python3") and args[:2] == ["-m", "pytest"]:
            assert " ".join(tokens) in (ROOT / ".ci" / "run").read_text(), (
                f"{self.where}: CI runs another test command"
            )
        elif program in ("python", "python3") and args and args[0].endswith(".py"):
            self.script(args[0], args[1:])
        else:
            self.fail(f"no way to run {' '.join(tokens)!r} here: say how in tests/test_docs.py")

    def kinlearn(self, args: list[str]) -> None:
        from kinlearn.cli.main import build_parser, main

        if args and "[" not in " ".join(args) and not self.parse_only("kinlearn", args):
            args = tiny_options(args)
            threads = torch.get_num_threads()
            try:
                code = main(args)
            except SystemExit as exc:  # argparse refused the command
                code = exc.code
            finally:
                torch.set_num_threads(threads)
            allowed = (0, 1) if args[0] == "plan" else (0,)
            assert code in allowed, f"{self.where}: kinlearn {' '.join(args)} exited with {code}"
            return
        self.parse(build_parser(), args, "kinlearn")

    def parse_only(self, program: str, args: list[str]) -> bool:
        return any(p == program and (w is None or w in args) for p, w in PARSE_ONLY)

    def parse(self, parser: argparse.ArgumentParser, args: list[str], name: str) -> None:
        if any(a.startswith("[") for a in args):  # a synopsis: the options it names must exist
            named = [a.strip("[]") for a in args if a.strip("[]").startswith("--")]
            for sub in parser._subparsers._group_actions if parser._subparsers else []:
                if args and args[0] in sub.choices:
                    parser = sub.choices[args[0]]
            unknown = [o for o in named if o not in parser._option_string_actions]
            assert not unknown, f"{self.where}: {name} has no option {unknown}"
            return
        try:
            parser.parse_args(args)
        except SystemExit as exc:
            self.fail(f"{name} {' '.join(args)}: refused by its parser (exit {exc.code})")

    def script(self, path: str, args: list[str]) -> None:
        """A benchmark script: its main() runs up to its parse_args, which parses ``args`` and stops."""
        file = Path(path)
        assert file.is_file(), f"{self.where}: no script {path}"

        class Parsed(Exception):
            pass

        parsers: list[argparse.ArgumentParser] = []

        def parse_args(parser, argv=None, namespace=None):
            parsers.append(parser)
            raise Parsed

        saved = sys.argv, list(sys.path)
        sys.argv, sys.path[:0] = [str(file)], [str(file.parent.resolve())]
        original = argparse.ArgumentParser.parse_args
        argparse.ArgumentParser.parse_args = parse_args
        try:
            module = runpy.run_path(str(file), run_name="docs_parse")
            assert "main" in module, f"{self.where}: {path} has no main()"
            module["main"]()
        except Parsed:
            pass
        finally:
            argparse.ArgumentParser.parse_args = original
            sys.argv, sys.path[:] = saved
        assert parsers, f"{self.where}: {path}'s main() parsed no arguments"
        self.parse(parsers[-1], args, path)


def tiny_options(args: list[str]) -> list[str]:
    sets = TINY_OPTIONS.get(args[0], {})
    parser_flags = {k for k, v in sets.items() if not v}
    out, i = [args[0]], 1
    while i < len(args):
        a = args[i]
        if a in sets:  # drop the doc's value; the tiny one is added below
            i += 1
            while i < len(args) and not args[i].startswith("--") and a not in parser_flags:
                i += 1
            continue
        out.append(a)
        i += 1
    for option, value in sets.items():
        out += [option, *value]
    return out


def lowered_defaults(monkeypatch) -> None:
    for cls, values in TINY_DEFAULTS.items():
        init = cls.__init__
        names = [f.name for f in dataclasses.fields(cls) if f.init and not f.kw_only]
        defaults = list(init.__defaults__ or ())
        for name, value in values.items():
            if name in names[len(names) - len(defaults) :]:
                defaults[names.index(name) - (len(names) - len(defaults))] = value
            else:
                kw = dict(init.__kwdefaults__ or {})
                assert name in kw, f"TINY_DEFAULTS: {cls.__name__} has no default {name!r}"
                kw[name] = value
                monkeypatch.setattr(init, "__kwdefaults__", kw)
        monkeypatch.setattr(init, "__defaults__", tuple(defaults))


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_doc_blocks_run(doc, tmp_path, monkeypatch):
    rel = doc.relative_to(ROOT).as_posix()
    runnable = [b for b in blocks(doc) if b.info in RUN]
    if not runnable:
        pytest.skip(f"{rel} has no block to run")
    for shipped in ("benchmarks", "examples", "robots"):  # what a clone holds
        (tmp_path / shipped).symlink_to(ROOT / shipped)
    (tmp_path / "kinlearn").mkdir()
    (tmp_path / "kinlearn" / "checkpoints").symlink_to(Path(kinlearn.__file__).parent / "checkpoints")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    lowered_defaults(monkeypatch)
    viewers = []
    try:
        from kinlearn.viz import viewer as viewer_module

        # A viewer that waits for Ctrl-C returns at once, closed, as after Ctrl-C.
        monkeypatch.setattr(viewer_module.PlanViewer, "wait", lambda self: self.close())
        init = viewer_module.PlanViewer.__init__

        def tracked(self, *a, **k):
            init(self, *a, **k)
            viewers.append(self)

        monkeypatch.setattr(viewer_module.PlanViewer, "__init__", tracked)
    except ImportError:
        pass
    robots = set(robot_module.ROBOTS)
    run = DocRun(rel)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the docs' own warnings (tiny models, domain)
            for command in PREREQUISITES.get(rel, []):
                run.kinlearn(shlex.split(command))
            if rel in READER_NAMES:
                run.ns["kinlearn"] = kinlearn
                run.python(READER_NAMES[rel], 0, tiny=False)
            for b in runnable:
                run.where = f"{rel}:{b.line}"
                included = re.fullmatch(r'--8<-- "([^"]+)"', b.text.strip())
                if included:  # a file shown whole (pymdownx.snippets): it must exist; test_examples runs it
                    assert (ROOT / included.group(1)).is_file(), f"{run.where}: no file {included.group(1)}"
                    continue
                if RUN[b.info] == "python":
                    run.python(b.text, b.line)
                else:
                    run.shell(b.text, b.line)
    finally:
        sys.modules.pop(run.module.__name__, None)
        for v in viewers:
            v.close()
        for name in set(robot_module.ROBOTS) - robots:
            robot_module.unregister_robot(name)
        os.chdir(ROOT)


def test_a_drifted_block_fails(tmp_path, monkeypatch):
    """The runner is no rubber stamp: a renamed option, a missing script, an unknown command, a bad
    synopsis or a Python name that no longer exists each fail the doc they are in."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "benchmarks").symlink_to(ROOT / "benchmarks")
    run = DocRun("README.md")
    drifted = [
        ("shell", "kinlearn make-endpoints --pairs 10 --run-dir runs/e"),  # the option is --n
        ("shell", "kinlearn reproduce --quick --workers 0"),  # parsed only, and 0 workers is refused
        ("shell", "python benchmarks/no_such_benchmark.py --n 3"),
        ("shell", "python benchmarks/plan_latency.py [--calls 10] [--no-rrt]"),
        ("shell", "make install"),
        ("python", "import kinlearn\nkinlearn.no_such_function()"),
    ]
    for kind, text in drifted:
        with pytest.raises((pytest.fail.Exception, AssertionError, AttributeError)):
            getattr(run, kind)(text, 1)
    assert tiny_options(["babble", "--transitions", "1000000", "--run-dir", "r"]) == [
        "babble",
        "--run-dir",
        "r",
        "--transitions",
        "3000",
        "--walkers",
        "50",
    ]
    run.shell("kinlearn make-endpoints --n 12000 --heldout 2000 --run-dir runs/e", 1)  # runs, tiny
    assert (tmp_path / "runs" / "e" / "config.json").is_file()


#: A Markdown link or image: ``[text](target)`` / ``![alt](target)``; the target up to a space or ``)``.
_LINK = re.compile(r"\]\(([^)\s]+)\)")


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_links_point_at_files(doc):
    """Every relative link and image of a doc (a figure, another doc, a source file) names a file of the
    repository, so that a renamed or never-committed figure fails here, not in a reader's browser."""
    missing = []
    for target in _LINK.findall(doc.read_text()):
        if re.match(r"[a-z]+:", target) or target.startswith("#"):  # a web address, a heading
            continue
        if not (doc.parent / target.split("#")[0]).exists():
            missing.append(target)
    assert not missing, f"{doc.name} links to files that do not exist: {missing}"


def test_the_shipped_log_is_babbling_with_its_stated_noise():
    """examples/data/iiwa14_log.csv, which the README's calibration reads, is what examples/data/make_log.py
    says it is: the bundled iiwa14's babbling, its positions off the analytic FK by 1 mm of noise per axis."""
    from kinlearn.data.recorded import load_recorded

    sys.path.insert(0, str(ROOT / "examples" / "data"))
    try:
        import make_log
    finally:
        sys.path.remove(str(ROOT / "examples" / "data"))
    obs = load_recorded(make_log.LOG, robot="iiwa14")
    cfg = make_log.CONFIG
    assert len(obs.theta) == cfg.walkers * (cfg.steps + 1) and int(obs.episode.max()) + 1 == cfg.walkers
    noise = obs.ef - kinlearn.kinematics(kinlearn.load_robot("iiwa14")).position(obs.theta)
    assert cfg.ef_noise == 0.001
    assert torch.allclose(noise.std(0), torch.full((3,), cfg.ef_noise, dtype=noise.dtype), rtol=0.1)
    assert float(noise.mean(0).abs().max()) < 1e-4
