"""A GIF of the arm moving along a joint path (matplotlib 3-D, written by matplotlib's Pillow writer).

One frame per configuration of the path: pass a plan's ``joints`` for one frame per step, or a timed
trajectory resampled at the frame rate (``time_parameterize(robot, plan.joints, dt=1 / fps)``, then
``q`` and ``times=t``) for motion at its real speed. Each frame shows the arm as a polyline through its
joint origins, the end-effector trace so far, the whole end-effector path (dashed), the start and the
goal, and optionally the planner's waypoints and obstacles (a :class:`~kinlearn.collision.Scene` as
``scene=``, or spheres ``(K, 4)`` ``[x, y, z, r]``, boxes ``(B, 6)`` ``[centre, half extents]`` or
``(B, 15)`` with a rotation, cylinders ``(C, 14)``). Every frame carries its index (and time),
so no two frames are identical and the GIF keeps exactly one frame per configuration.

matplotlib (``pip install kinlearn[plots]``) is imported when an animation is made, through its
object-oriented API only (no pyplot, no global backend change). The GIF is written atomically.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ..body.robot import Robot
from ..checks import as_int, as_real
from ..collision.geometry import box_faces, cylinder_faces
from ..errors import ConfigError, MissingDependencyError
from ..io import atomic_write, check_output
from ._scene import PlanScene, plan_scene

__all__ = ["animate_plan"]

#: The most frames an animation draws (each takes tens of milliseconds): a bound on its time and size.
MAX_FRAMES = 5000

_ARM = "#3b3b3b"
_TRACE = "#1f77b4"
_WAYPOINT = "#ff7f0e"
_OBSTACLE = "#d62728"


def _matplotlib():
    try:
        import mpl_toolkits.mplot3d  # noqa: F401  (registers the "3d" projection)
        from matplotlib.animation import PillowWriter
        from matplotlib.figure import Figure
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    except ImportError as exc:
        raise MissingDependencyError(
            "kinlearn's animations need matplotlib, which is not installed: "
            "`pip install matplotlib` (or `pip install kinlearn[plots]`)"
        ) from exc
    return Figure, PillowWriter, Poly3DCollection


def _draw_static(ax, scene: PlanScene, Poly3DCollection) -> None:
    ee = scene.ee
    ax.plot(*ee.T, color=_TRACE, lw=1.0, ls="--", alpha=0.5, label="end-effector path")
    ax.scatter(*ee[0], color="#2ca02c", s=40, marker="o", depthshade=False, label="start")
    ax.scatter(*ee[-1], color=_OBSTACLE, s=80, marker="*", depthshade=False, label="goal")
    if len(scene.waypoints):
        ax.scatter(
            *scene.waypoints.T,
            facecolors="none",
            edgecolors=_WAYPOINT,
            s=30,
            linewidths=1.2,
            depthshade=False,
            label="waypoints",
        )
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 16), np.linspace(0, np.pi, 9))
    for x, y, z, r in scene.spheres:
        ax.plot_surface(
            x + r * np.cos(u) * np.sin(v),
            y + r * np.sin(u) * np.sin(v),
            z + r * np.cos(v),
            color=_OBSTACLE,
            alpha=0.25,
            linewidth=0,
        )
    faces = [f for box in scene.boxes for f in box_faces(box)]
    faces += [f for cyl in scene.cylinders for f in cylinder_faces(cyl)]
    if faces:
        ax.add_collection3d(
            Poly3DCollection(faces, facecolor=_OBSTACLE, alpha=0.2, edgecolor=_OBSTACLE, lw=0.5)
        )


def _set_view(ax, scene: PlanScene, elev: float, azim: float) -> None:
    from matplotlib.ticker import MaxNLocator

    lo, hi = scene.bounds()
    centre, half = (lo + hi) / 2, max(float((hi - lo).max()) / 2, 0.1) * 1.05
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=elev, azim=azim)
    for axis, name in ((ax.xaxis, "x"), (ax.yaxis, "y"), (ax.zaxis, "z")):
        axis.set_major_locator(MaxNLocator(4))
        axis.set_tick_params(labelsize=7, pad=0)
        axis.set_label_text(f"{name} (m)", fontsize=8)


def animate_plan(
    robot: Robot,
    joints: Any,
    path: str | Path,
    *,
    waypoints: Any = None,
    spheres: Any = None,
    boxes: Any = None,
    times: Any = None,
    cylinders: Any = None,
    scene: Any = None,
    fps: float = 20.0,
    figsize: tuple[float, float] = (5.0, 5.0),
    dpi: int = 80,
    elev: float = 20.0,
    azim: float = -60.0,
    title: str | None = None,
) -> Path:
    """Write a GIF of ``robot`` moving along ``joints`` to ``path``; returns the path.

    Args:
        robot: the robot (``kinlearn.load_robot(name)``).
        joints: ``(N, dof)`` joint path (tensor or array, rad); one frame per row.
        path: the GIF file to write.
        waypoints: ``(M, 3)`` points to mark (e.g. a plan's ``waypoints``), metres.
        spheres: ``(K, 4)`` obstacle spheres ``[x, y, z, r]``; boxes: ``(B, 6)`` ``[centre, half extents]``
            or ``(B, 15)`` (with a rotation); cylinders: ``(C, 14)``; or all of them as ``scene``, a
            :class:`~kinlearn.collision.Scene`.
        times: ``(N,)`` time stamps (s) shown on each frame, e.g. a timed trajectory's ``t``.
        fps: frames per second of the GIF (GIF delays are whole centiseconds: 20 fps or 25 fps are exact).
        figsize, dpi: the frame size in inches and its resolution (5 in × 80 dpi = 400 px).
        elev, azim: the 3-D view's elevation and azimuth in degrees.
        title: a title over the frames (default: the robot's name).

    Raises:
        ShapeError, NonFiniteError, ConfigError: malformed inputs. MissingDependencyError: no matplotlib.
    """
    fps = as_real(fps, "fps", minimum=0.0, open_minimum=True, maximum=100.0)
    dpi = as_int(dpi, "dpi", minimum=1, maximum=1000)
    path = check_output(path)  # before the seconds of drawing, not after
    if path.suffix.lower() != ".gif":
        raise ConfigError(f"an animation is written as a GIF: give a path ending in .gif, got {str(path)!r}")
    scene = plan_scene(
        robot,
        joints,
        waypoints=waypoints,
        spheres=spheres,
        boxes=boxes,
        times=times,
        cylinders=cylinders,
        scene=scene,
    )
    if scene.frames > MAX_FRAMES:
        raise ConfigError(
            f"{scene.frames} configurations would make {scene.frames} frames, more than the {MAX_FRAMES} an "
            "animation draws (MAX_FRAMES, tens of milliseconds each); pass every k-th configuration"
        )
    Figure, PillowWriter, Poly3DCollection = _matplotlib()

    fig = Figure(figsize=figsize)
    ax = fig.add_subplot(projection="3d")
    fig.subplots_adjust(left=0.0, right=1.0, bottom=0.02, top=0.93)
    _set_view(ax, scene, elev, azim)
    _draw_static(ax, scene, Poly3DCollection)
    (arm,) = ax.plot([], [], [], color=_ARM, lw=5, marker="o", ms=6, mfc="white", label="arm")
    (trace,) = ax.plot([], [], [], color=_TRACE, lw=2.5)
    ax.set_title(title if title is not None else robot.name, fontsize=11)
    label = fig.text(0.98, 0.02, "", ha="right", fontsize=8, family="monospace")
    ax.legend(loc="upper left", fontsize=7, frameon=False)

    n = scene.frames

    def write(tmp: Path) -> None:
        # Pillow picks the format from the file name: render to a ".gif" beside the temporary file.
        gif = tmp.with_name(tmp.name + ".gif")
        writer = PillowWriter(fps=fps)
        try:
            with writer.saving(fig, str(gif), dpi):
                for i in range(n):
                    links = scene.links[i]
                    arm.set_data_3d(links[:, 0], links[:, 1], links[:, 2])
                    trace.set_data_3d(*scene.ee[: i + 1].T)
                    when = "" if scene.times is None else f"t = {scene.times[i]:6.2f} s   "
                    label.set_text(f"{when}{i + 1}/{n}")
                    writer.grab_frame()
            os.replace(gif, tmp)
        finally:
            gif.unlink(missing_ok=True)

    return atomic_write(path, write)
