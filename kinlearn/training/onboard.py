"""From a URDF to a planner among obstacles, in one call: :func:`onboard`.

The steps, each into its own folder of the run directory, each the library's own training function:

=============  ==========================================================================================
``robot/``     collision spheres fitted to the URDF's collision geometry
               (:func:`kinlearn.collision.spherize.spherize`): ``<name>_spherized.urdf`` and
               ``collision_spheres.json``; ``robot.json`` names the URDF, the end-effector frame and them
``babble/``    motor babbling (:func:`kinlearn.data.babbling.babble`)
``fm/``        the learned forward model (:func:`~kinlearn.training.forward_inverse.train_fm`)
``im/``        the learned inverse model, then refined through the FM (``train_im``, ``train_im_distal``)
``identify/``  the kinematic chain identified from the babbling alone (:func:`~kinlearn.training.identify`)
``planner/``   the free-space joint-path TM through the FM (:func:`~kinlearn.training.joint_path.
               train_path_model`), beside ``fm.pt``, ``im.pt`` and ``chain.pt``: the planner folder
``problems/``  training problems of the seven scene families, scaled to the arm
``obstacles/`` the obstacle-aware TM (:func:`~kinlearn.training.obstacle_path.train_obstacle_model`),
               exported into ``planner/tm_obstacles.pt``
=============  ==========================================================================================

``steps.json`` records the steps done: ``resume=True`` skips them and continues the one that was cut off
(the trainers resume from their checkpoints). After it, :func:`load_onboarded` registers the robot in
a process (with its spheres and its planner), so that ``Planner.load(run_dir / "planner")`` and
``plan(..., robot=NAME)`` plan with it.

URDFs it cannot take raise :class:`~kinlearn.errors.RobotDescriptionError` saying what to do: no
collision geometry on the chain, a prismatic joint on the chain, joints that move links off the chain
anywhere but below its last link (a second arm, a head: not a serial chain to the end-effector frame).
"""

from __future__ import annotations

import dataclasses
import re
import time
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

from ..body.robot import BUILTIN_ROBOTS, Robot, load_robot, register_robot
from ..collision.spherize import SpherizeConfig
from ..errors import ConfigError, KinlearnWarning, PlanningError, RobotDescriptionError
from ..io import read_json, write_json
from ..runs import open_run

__all__ = [
    "ONBOARD_SIZES",
    "OnboardConfig",
    "OnboardResult",
    "check_onboardable",
    "load_onboarded",
    "onboard",
]

#: The steps of :func:`onboard`, in order.
STEPS = ("spheres", "babble", "fm", "im", "identify", "planner", "problems", "obstacles")


@dataclass(frozen=True)
class OnboardConfig:
    """The sizes of :func:`onboard`'s steps (see :data:`ONBOARD_SIZES` for named ones). ``families``: the
    scene families the obstacle network trains on (names or ``"scenes"``, the seven); ``max_attempts``:
    scenes tried per training problem (a small arm finds a free pose in a cell in fewer of them)."""

    transitions: int = 300_000
    fm_epochs: int = 30
    fk_hidden: tuple[int, ...] = (128, 128, 128)
    im_epochs: int = 20
    im_through_fm_epochs: int = 8
    planner_iterations: int = 3000
    planner_batch_size: int = 512
    problems_per_family: int = 120
    obstacle_iterations: int = 1500
    obstacle_batch_size: int = 64
    candidates: int = 16
    max_attempts: int = 400
    families: tuple[str, ...] = ("scenes",)
    solvable_only: bool = True
    identify: bool = True
    spheres: SpherizeConfig = field(default_factory=SpherizeConfig)
    seed: int = 0

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            low = 0 if f.name == "seed" else 1
            if f.type == "int" and (isinstance(v, bool) or not isinstance(v, int) or v < low):
                raise ConfigError(f"OnboardConfig.{f.name} must be an integer ≥ {low}, got {v!r}")
        if not (isinstance(self.spheres, SpherizeConfig) and self.fk_hidden and min(self.fk_hidden) >= 1):
            raise ConfigError("OnboardConfig.spheres must be a SpherizeConfig and fk_hidden positive widths")

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> OnboardConfig:
        d = dict(d)
        d["spheres"] = SpherizeConfig(**d.get("spheres", {}))
        d["fk_hidden"] = tuple(d.get("fk_hidden", (128, 128, 128)))
        d["families"] = tuple(d.get("families", ("scenes",)))
        return cls(**d)


#: Named sizes: ``tiny`` (seconds; tests), ``small`` (minutes: a first look), ``default`` (the shipped
#: arms' sizes for the free-space planner, a lighter obstacle training).
ONBOARD_SIZES: dict[str, OnboardConfig] = {
    "tiny": OnboardConfig(
        transitions=4000,
        fm_epochs=1,
        fk_hidden=(32, 32),
        im_epochs=1,
        im_through_fm_epochs=1,
        planner_iterations=20,
        planner_batch_size=64,
        problems_per_family=2,
        obstacle_iterations=10,
        obstacle_batch_size=8,
        candidates=4,
        max_attempts=60,
        families=("cage", "wall", "clutter"),
        solvable_only=False,
        spheres=SpherizeConfig(
            fit_points=400, check_points=2000, voxels=12, candidates=150, radii=8, samples=200
        ),
    ),
    "small": OnboardConfig(
        transitions=100_000,
        fm_epochs=10,
        im_epochs=8,
        im_through_fm_epochs=3,
        planner_iterations=1000,
        problems_per_family=60,
        obstacle_iterations=800,
    ),
    "default": OnboardConfig(),
}


@dataclass
class OnboardResult:
    """What :func:`onboard` made: the robot (registered in this process), the run directory, the planner
    folder, the sphere model, and the seconds each step took (this call's)."""

    robot: Robot
    run_dir: Path
    planner: Path
    spheres: Path
    seconds: dict


def _chain_links(root: ET.Element, robot: Robot) -> tuple[str, set[str]]:
    """The base link and the set of links on the chain (root to the last moving joint's child)."""
    by_name = {el.get("name"): el for el in root.findall("joint")}
    base = by_name[robot.joints[0].name].find("parent").get("link")
    on = {base}
    for j in robot.joints:
        el = by_name[j.name]
        on.add(el.find("child").get("link"))
    return base, on


def check_onboardable(robot: Robot) -> None:
    """Raise :class:`~kinlearn.errors.RobotDescriptionError`, saying what to do, for an arm :func:`onboard`
    cannot take: a prismatic joint on the chain, or joints moving links off the chain anywhere but below
    its last link (the chain's collision geometry is checked where spheres are fitted)."""
    prismatic = [j.name for j in robot.joints if j.kind == "prismatic"]
    if prismatic:
        raise RobotDescriptionError(
            f"{robot.name}: the chain to {robot.ee_frame!r} has prismatic joints ({', '.join(prismatic)}); "
            "onboard takes arms of revolute joints: fix them in the URDF (type='fixed') or choose an "
            "end-effector frame before them"
        )
    root = ET.fromstring(robot.urdf)
    base, on = _chain_links(root, robot)
    by_child = {el.find("child").get("link"): el for el in root.findall("joint")}
    last = next(el for el in root.findall("joint") if el.get("name") == robot.joints[-1].name)
    tip = last.find("child").get("link")
    chain_names = set(robot.joint_names)
    stray = []
    for el in root.findall("joint"):
        if el.get("type") in ("fixed", "floating", "planar") or el.get("name") in chain_names:
            continue
        # a moving joint off the chain: allowed below the chain's last link (a gripper, a jaw)
        cur, below = el.find("parent").get("link"), False
        while cur is not None:
            if cur == tip:
                below = True
                break
            if cur in on:
                break
            j = by_child.get(cur)
            cur = j.find("parent").get("link") if j is not None else None
        if not below:
            stray.append(el.get("name"))
    if stray:
        raise RobotDescriptionError(
            f"{robot.name}: joints {', '.join(stray[:8])} move links that are not on the serial chain from "
            f"{base!r} to {robot.ee_frame!r} (a tree, not one arm); onboard takes one serial arm: fix those "
            "joints in the URDF (type='fixed'), remove their links, or choose the end-effector frame of the arm"
        )


def _name_of(urdf: Path, name: str | None) -> str:
    name = name or re.sub(r"[^A-Za-z0-9_.+-]", "_", urdf.stem)
    if name in BUILTIN_ROBOTS:
        raise ConfigError(
            f"{name!r} is one of kinlearn's own robots; onboard your URDF under another name (name=, --name)"
        )
    return name


def load_onboarded(run_dir: str | Path) -> Robot:
    """Register the robot an :func:`onboard` run made (its URDF, end-effector frame, fitted spheres and
    planner folder) in this process, and return it: ``plan(..., robot=NAME)`` then plans with it."""
    run_dir = Path(run_dir)
    rec_path = run_dir / "robot" / "robot.json"
    if not rec_path.is_file():
        raise ConfigError(f"{run_dir} holds no onboarded robot (no robot/robot.json); run `kinlearn onboard`")
    rec = read_json(rec_path)
    robot = register_robot(
        rec["name"],
        rec["urdf"],
        rec["ee_frame"],
        spheres=run_dir / "robot" / "collision_spheres.json",
        overwrite=True,
        description=f"onboarded from {Path(rec['urdf']).name}",
    )
    planner = run_dir / "planner"
    if (planner / "tm.pt").is_file():
        robot.planner_dir = planner
    return robot


def onboard(
    urdf: str | Path,
    ee_frame: str,
    run_dir: str | Path,
    *,
    name: str | None = None,
    config: OnboardConfig | str = "default",
    srdf: str | Path | None = None,
    package_dirs: tuple = (),
    resume: bool = False,
    overwrite: bool = False,
    progress: bool = True,
) -> OnboardResult:
    """Fit spheres to ``urdf``'s collision geometry, babble, train the FM and IM, identify the chain,
    train the free-space planner and the obstacle network on the seven scene families scaled to the
    arm, into ``run_dir`` (see the module docstring). ``config``: an :class:`OnboardConfig` or a name of
    :data:`ONBOARD_SIZES`. ``srdf``: its ``disable_collisions`` pairs are left out of self-collision.
    ``package_dirs``: where ``package://`` meshes are found. ``resume``/``overwrite``: the run-directory
    rules (:mod:`kinlearn.runs`). Returns an :class:`OnboardResult`; the robot stays registered."""
    from ..collision.spherize import spherize, write_sphere_model
    from ..io import file_sha256

    if isinstance(config, str):
        if config not in ONBOARD_SIZES:
            raise ConfigError(f"unknown onboard size {config!r}; choose one of {', '.join(ONBOARD_SIZES)}")
        config = ONBOARD_SIZES[config]
    urdf = Path(urdf).resolve()
    if not urdf.is_file():
        raise ConfigError(f"no URDF file at {urdf}")
    name = _name_of(urdf, name)
    robot = load_robot(urdf, ee_frame)  # parses the chain: a bad file or frame fails here
    check_onboardable(robot)
    run_dir = Path(run_dir)
    record = {
        "robot": name,
        "urdf": {"path": str(urdf), "sha256": file_sha256(urdf)},
        "ee_frame": ee_frame,
        "srdf": str(srdf) if srdf is not None else None,
        "onboard": config.to_dict(),
    }
    run = open_run(
        run_dir, command="onboard", config=record, outputs=(*_OUTPUTS, "steps.json"), resume=resume,
        overwrite=overwrite,
    )  # fmt: skip
    run_dir = run.begin()
    steps_path = run_dir / "steps.json"
    done: dict = read_json(steps_path) if (run.resumed and steps_path.is_file()) else {}
    seconds: dict = {}

    def step(key: str, fn) -> None:
        if key in done:
            return
        t0 = time.perf_counter()
        if progress:
            print(f"onboard {name}: {key} …", flush=True)
        fn(run.resumed)
        seconds[key] = time.perf_counter() - t0
        done[key] = {"seconds": seconds[key]}
        write_json(steps_path, done)

    robot_dir = run_dir / "robot"
    model_json = robot_dir / "collision_spheres.json"

    def fit_spheres(_resumed: bool) -> None:
        robot_dir.mkdir(parents=True, exist_ok=True)
        bar = _bar(progress, "spheres (links)")
        fit = spherize(
            robot, srdf=srdf, config=config.spheres, package_dirs=package_dirs,
            progress=(lambda k, n: bar(k, n)) if bar else None,
        )  # fmt: skip
        write_sphere_model(fit, _renamed(robot, name, urdf, ee_frame), robot_dir)
        write_json(
            robot_dir / "robot.json",
            {"name": name, "urdf": str(urdf), "ee_frame": ee_frame, "srdf": record["srdf"]},
        )

    step("spheres", fit_spheres)
    robot = load_onboarded(run_dir)  # registered under its name, with its spheres
    _run_steps(robot, run_dir, config, step, progress)
    robot = load_onboarded(run_dir)
    return OnboardResult(robot, run_dir, run_dir / "planner", model_json, seconds)


_OUTPUTS = ("robot", "babble", "fm", "im", "identify", "planner", "problems", "obstacles")


def _renamed(robot: Robot, name: str, urdf: Path, ee_frame: str) -> Robot:
    """The robot under ``name`` (the sphere model records the robot it is for)."""
    return Robot(name, urdf.read_bytes(), ee_frame, urdf)


def _bar(progress: bool, what: str):
    if not progress:
        return None
    from tqdm import tqdm

    state: dict = {}

    def update(k: int, n: int) -> None:
        if "bar" not in state:
            state["bar"] = tqdm(total=n, desc=what, leave=False)
        state["bar"].update(k - state["bar"].n)
        if k >= n:
            state["bar"].close()

    return update


def _run_steps(robot: Robot, run_dir: Path, config: OnboardConfig, step, progress: bool) -> None:
    import torch

    from ..data.babbling import BabblingConfig, babble, load_transitions, save_transitions
    from ..data.problems import select_families
    from ..io import atomic_copy
    from ..models.forward_inverse import load_fm
    from ..models.obstacle_path import export_obstacle_model
    from ..models.presets import fm_config, im_config
    from .forward_inverse import THROUGH_FM_ACTION_WEIGHT, train_config, train_fm, train_im, train_im_distal
    from .identify import IdentifyConfig, identify
    from .joint_path import PathTrainConfig, train_path_model
    from .obstacle_path import ObstacleTrainConfig, make_training_problems, train_obstacle_model

    name, seed = robot.name, config.seed
    torch.set_num_threads(max(1, torch.get_num_threads()))
    data_path = run_dir / "babble" / "babbling.npz"

    def do_babble(_r: bool) -> None:
        cfg = BabblingConfig.for_transitions(
            config.transitions, walkers=min(1000, config.transitions), robot=name, seed=seed
        )
        (run_dir / "babble").mkdir(parents=True, exist_ok=True)
        save_transitions(babble(cfg), data_path)

    step("babble", do_babble)
    data = load_transitions(data_path)

    def do_fm(resumed: bool) -> None:
        model = fm_config(name, "improved", fk_hidden=tuple(config.fk_hidden))
        cfg = train_config("fm", "improved", epochs=config.fm_epochs, seed=seed, progress=progress)
        train_fm(
            data, model, cfg, run_dir=run_dir / "fm", resume=resumed and (run_dir / "fm" / "fm.pt").is_file()
        )

    step("fm", do_fm)
    fm = load_fm(run_dir / "fm" / "fm.pt", robot=name)

    def do_im(resumed: bool) -> None:
        sup = run_dir / "im" / "supervised"
        cfg = train_config(
            "im", "improved", epochs=config.im_epochs, batch_size=1024, seed=seed, progress=progress
        )
        res = train_im(
            data, im_config(name, "improved"), cfg, run_dir=sup, resume=resumed and (sup / "im.pt").is_file()
        )
        dcfg = train_config(
            "im",
            "improved",
            epochs=config.im_through_fm_epochs,
            batch_size=1024,
            seed=seed,
            progress=progress,
        )
        through = run_dir / "im" / "through-fm"
        distal = train_im_distal(
            data, res.model, fm, dcfg, run_dir=through, resume=resumed and (through / "im.pt").is_file(),
            action_weight=THROUGH_FM_ACTION_WEIGHT,
        )  # fmt: skip
        atomic_copy(distal.checkpoint, run_dir / "im" / "im.pt")

    step("im", do_im)

    def do_identify(_r: bool) -> None:
        (run_dir / "identify").mkdir(parents=True, exist_ok=True)
        cfg = IdentifyConfig(seed=seed)
        result = identify(data, robot=robot, prior=False, config=cfg, progress=progress)
        result.save(run_dir / "identify" / "chain.pt", cfg)
        write_json(run_dir / "identify" / "report.json", result.report)

    if config.identify:
        step("identify", do_identify)
    planner = run_dir / "planner"

    def do_planner(resumed: bool) -> None:
        planner.mkdir(parents=True, exist_ok=True)
        atomic_copy(run_dir / "fm" / "fm.pt", planner / "fm.pt")
        atomic_copy(run_dir / "im" / "im.pt", planner / "im.pt")
        if config.identify:
            atomic_copy(run_dir / "identify" / "chain.pt", planner / "chain.pt")
        cfg = PathTrainConfig(
            robot=name, fm="learned", fm_checkpoint="fm.pt", iterations=config.planner_iterations,
            batch_size=config.planner_batch_size, max_step=fm.max_step, model={"modes": 8}, seed=seed,
        )  # fmt: skip
        train_path_model(
            cfg, planner, fm=fm, resume=resumed and (planner / "tm.pt").is_file(), progress=progress
        )

    step("planner", do_planner)
    families = select_families(list(config.families))

    def do_problems(_r: bool) -> None:
        bar = _bar(progress, "problem families")
        made, failed = [], []
        for k, fam in enumerate(families):
            try:
                make_training_problems(
                    run_dir / "problems", config.problems_per_family, robot=robot, families=(fam,),
                    max_attempts=config.max_attempts,
                )  # fmt: skip
                made.append(fam)
            except PlanningError as exc:  # no free start and goal for this arm in the family's scenes
                failed.append(fam)
                warnings.warn(
                    f"onboard {name}: no {fam} training problems ({exc}); the obstacle network trains without "
                    "that family",
                    KinlearnWarning,
                    stacklevel=2,
                )
            if bar:
                bar(k + 1, len(families))
        if not made:
            raise ConfigError(
                f"onboard {name}: no training problem of any scene family could be made for this arm (its body "
                "fills the scenes' cells): check the fitted spheres in robot/, or raise max_attempts"
            )
        write_json(run_dir / "problems" / "families.json", {"made": made, "not_made": failed})

    step("problems", do_problems)
    made = tuple(read_json(run_dir / "problems" / "families.json")["made"])
    problem_paths = make_training_problems(
        run_dir / "problems",
        config.problems_per_family,
        robot=robot,
        families=made,
        max_attempts=config.max_attempts,
    )  # made already: the same files, checked

    def do_obstacles(resumed: bool) -> None:
        cfg = ObstacleTrainConfig(
            robot=name, problems=tuple(sorted(str(p) for p in problem_paths)), iterations=config.obstacle_iterations,
            batch_size=config.obstacle_batch_size, model={"candidates": config.candidates},
            solvable_only=config.solvable_only, seed=seed,
        )  # fmt: skip
        out = run_dir / "obstacles"
        train_obstacle_model(
            cfg, out, resume=resumed and (out / "tm_obstacles.pt").is_file(), progress=progress
        )
        export_obstacle_model(out / "tm_obstacles.pt", planner / "tm_obstacles.pt")

    step("obstacles", do_obstacles)
