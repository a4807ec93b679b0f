"""One way in for every file kinlearn writes: :func:`load` reads a checkpoint or a run directory and
returns what it holds, by the kind the file records."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from .errors import CheckpointError

__all__ = ["CHECKPOINT_KINDS", "load"]

#: What :func:`load` returns for each checkpoint kind.
CHECKPOINT_KINDS = {
    "fm": "a forward model (LearnedFM, AnalyticFM, or ChainFM; an identification's chain: Identification)",
    "im": "an inverse model (LearnedIM or AnalyticIM)",
    "tm": "the paper's waypoint trajectory model (TrajectoryModel)",
    "tm-imitation": "a trajectory model trained by imitation (TrajectoryModel)",
    "tm-joint-path": "a joint-path trajectory model (JointPathModel)",
    "tm-obstacle-path": "an obstacle-aware trajectory model (ObstaclePathModel)",
    "body": "a learned body model (LearnedBody)",
}
#: The file in a run directory that says what the directory is (first found wins).
_RUN_FILES = ("tm.pt", "chain.pt")


def load(path: str | Path, robot: str | None = None) -> Any:
    """What the checkpoint file or run directory at ``path`` holds, ready to use (eval mode).

    - A directory holding ``tm.pt`` (a trained or exported planner): the
      :class:`~kinlearn.planning.planner.Planner` (:meth:`Planner.load <kinlearn.planning.planner.Planner.load>`).
    - A directory holding ``chain.pt`` (a run of ``kinlearn identify``), or an FM checkpoint saved by
      an identification (its report): the :class:`~kinlearn.training.identify.Identification`.
    - A checkpoint file: the model of its kind (:data:`CHECKPOINT_KINDS`) by that kind's loader
      (:func:`~kinlearn.models.load_fm`, :func:`~kinlearn.models.load_im`,
      :func:`~kinlearn.train.load_tm` for a waypoint TM, without resolving the FM/IM it was trained through,
      :func:`~kinlearn.models.load_path_model`, :func:`~kinlearn.models.load_obstacle_model`,
      :func:`~kinlearn.models.load_body_model`).

    ``robot``: the robot's name the file must be for (``None``: any). Raises
    :class:`~kinlearn.errors.CheckpointError` for a missing path, a directory holding neither file, a
    file that is no kinlearn checkpoint, and a kind this kinlearn does not know.
    """
    from .io import load_checkpoint

    path = Path(path)
    if path.is_dir():
        found = next((path / name for name in _RUN_FILES if (path / name).is_file()), None)
        if found is None:
            held = sorted(p.name for p in path.iterdir() if p.suffix == ".pt")
            raise CheckpointError(
                f"{path} holds no planner (tm.pt) and no identified chain (chain.pt)"
                + (f"; load one of its checkpoints instead: {', '.join(held)}" if held else "")
            )
        if found.name == "tm.pt":
            from .planning.planner import Planner

            return Planner.load(path, robot=robot)
        return _identification_or_fm(found, load_checkpoint(found, kind="fm", robot=robot), robot)
    if not path.exists():
        raise CheckpointError(f"no checkpoint file or run directory at {path}")
    payload = load_checkpoint(path, kind=None, robot=robot)
    kind = payload.get("kind")
    if kind == "fm":
        return _identification_or_fm(path, payload, robot)
    if kind == "im":
        from .models.checkpoint import load_im

        return load_im(path, robot=robot)
    if kind == "tm":
        from .training.tm import load_tm

        return load_tm(path, robot=robot, resolve=False)[0].eval()
    if kind == "tm-imitation":
        from .training.imitation import load_imitation

        return load_imitation(path, robot=robot)
    if kind == "tm-joint-path":
        from .models.joint_path import load_path_model

        return load_path_model(path, robot=robot)
    if kind == "tm-obstacle-path":
        from .models.obstacle_path import load_obstacle_model

        return load_obstacle_model(path, robot=robot)
    if kind == "body":
        from .models.body import load_body_model

        return load_body_model(path, robot=robot)
    raise CheckpointError(
        f"{path} holds a checkpoint of kind {kind!r}, which this kinlearn cannot load; known kinds: "
        + ", ".join(CHECKPOINT_KINDS)
    )


def _identification_or_fm(path: Path, payload: dict, robot: str | None):
    """The FM checkpoint at ``path`` (read as ``payload``): the :class:`Identification` where an
    identification saved it (it records its report), else the forward model alone."""
    from .models.checkpoint import load_fm

    if "report" in payload["extra"]:
        from .training.identify import Identification

        return Identification.load(path)
    return load_fm(path, robot=robot)
