"""An interactive 3-D view of a plan in the browser, served by viser.

**Library: viser.** Both viser and meshcat serve a three.js scene from Python to a browser tab, and
both install from PyPI with their web client inside the wheel (no network needed at run time). viser
is chosen because it is actively maintained (meshcat-python's last release is from 2021) and because
it has GUI controls built in — a frame slider, a play checkbox and a speed field are plain Python
calls — where meshcat would need its animation clips built and replayed client-side.

The scene (z up, metres, the robot's base frame):

- ``/arm/link_<i>``: a cylinder between consecutive joint origins (base → joints → end effector;
  segments of zero length, where two joint origins coincide, have none), ``/arm/joint_<i>``: a sphere
  at each origin, ``/arm/ee``: the end effector. The URDF's meshes are not used.
- ``/path/executed``: the end-effector path of the joint path (line segments), ``/path/start`` and
  ``/path/goal``: its ends.
- ``/waypoints/<k>``: the planner's waypoints, if given.
- ``/obstacles/sphere_<k>``, ``/obstacles/box_<k>``: obstacles, if given.
- ``/grid``: the floor (z = 0).

The GUI has a ``frame`` slider over the path's configurations, a ``play`` checkbox and ``fps``.
viser is an optional extra (``pip install kinlearn[viewer]``), imported when a viewer starts.
"""

from __future__ import annotations

import contextlib
import threading
from typing import Any

import numpy as np

from ..body.robot import Robot
from ..checks import as_int
from ..collision.geometry import quaternion_from_rotation
from ..errors import ConfigError, MissingDependencyError
from ._scene import PlanScene, plan_scene

__all__ = ["PlanViewer", "show_plan"]

_ARM = (60, 62, 70)
_JOINT = (230, 230, 235)
_EE = (31, 119, 180)
_PATH = (31, 119, 180)
_WAYPOINT = (255, 127, 14)
_START = (44, 160, 44)
_GOAL = (214, 39, 40)
_OBSTACLE = (214, 39, 40)
_LINK_RADIUS = 0.035
_JOINT_RADIUS = 0.045
_MIN_LINK = 1e-6  # m: shorter segments get no cylinder


def _viser():
    try:
        import viser
    except ImportError as exc:
        raise MissingDependencyError(
            "kinlearn's browser viewer needs viser, which is not installed: "
            "`pip install viser` (or `pip install kinlearn[viewer]`)"
        ) from exc
    return viser


def _quat_z_to(d: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) rotating the z axis onto the unit vector ``d``."""
    z = np.array([0.0, 0.0, 1.0])
    c = float(np.dot(z, d))
    if c < -1.0 + 1e-12:  # opposite: half a turn about x
        return np.array([0.0, 1.0, 0.0, 0.0])
    axis = np.cross(z, d)
    q = np.array([1.0 + c, *axis])
    return q / np.linalg.norm(q)


class PlanViewer:
    """A running viewer of one plan. Returned by :func:`show_plan`; close it with :meth:`close`.

    Attributes:
        scene: the :class:`~kinlearn.viz._scene.PlanScene` drawn (arm joint origins per frame,
            end-effector path, waypoints, obstacles).
        nodes: scene-node name → viser handle, for every node this viewer added.
        server: the ``viser.ViserServer``; ``host``, ``port``, ``url`` where it listens.
        slider, playing, fps: the GUI handles (frame slider, play checkbox, frames per second).
    """

    def __init__(self, robot: Robot, scene: PlanScene, host: str, port: int, fps: float):
        viser = _viser()
        self.robot = robot
        self.scene = scene
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.host, self.port = host, int(self.server.get_port())
        self.nodes: dict[str, Any] = {}
        self._closed = threading.Event()
        self._lock = threading.Lock()
        links = scene.links[0]
        self._link_pairs = [
            i for i in range(links.shape[0] - 1) if np.linalg.norm(links[i + 1] - links[i]) > _MIN_LINK
        ]
        try:
            self._build(fps)
            self.set_frame(0)
        except BaseException:
            self.server.stop()
            raise
        self._player = threading.Thread(target=self._play_loop, name="kinlearn-viewer-play", daemon=True)
        self._player.start()

    # ------------------------------------------------------------------ scene

    def _add(self, name: str, handle: Any) -> None:
        self.nodes[name] = handle

    def _build(self, fps: float) -> None:
        s, sc = self.scene, self.server.scene
        sc.set_up_direction("+z")
        lo, hi = s.bounds()
        extent = float(max(hi[0] - lo[0], hi[1] - lo[1], 1.0)) * 1.5
        self._add("/grid", sc.add_grid("/grid", width=extent, height=extent, cell_size=0.1, section_size=0.5))
        links = s.links[0]
        for i in self._link_pairs:
            length = float(np.linalg.norm(links[i + 1] - links[i]))
            name = f"/arm/link_{i}"
            self._add(name, sc.add_cylinder(name, radius=_LINK_RADIUS, height=length, color=_ARM))
        for i in range(links.shape[0] - 1):
            name = f"/arm/joint_{i}"
            self._add(name, sc.add_icosphere(name, radius=_JOINT_RADIUS, color=_JOINT))
        self._add("/arm/ee", sc.add_icosphere("/arm/ee", radius=_JOINT_RADIUS * 0.8, color=_EE))
        ee = s.ee
        if len(ee) > 1:
            segs = np.stack([ee[:-1], ee[1:]], axis=1)
            self._add("/path/executed", sc.add_line_segments("/path/executed", segs, _PATH, thickness=0.01))
        self._add("/path/start", sc.add_icosphere("/path/start", radius=0.02, color=_START, position=ee[0]))
        self._add("/path/goal", sc.add_icosphere("/path/goal", radius=0.025, color=_GOAL, position=ee[-1]))
        for k, p in enumerate(s.waypoints):
            name = f"/waypoints/{k}"
            self._add(name, sc.add_icosphere(name, radius=0.012, color=_WAYPOINT, position=p))
        for k, (x, y, z, r) in enumerate(s.spheres):
            name = f"/obstacles/sphere_{k}"
            self._add(
                name,
                sc.add_icosphere(name, radius=float(r), color=_OBSTACLE, opacity=0.45, position=(x, y, z)),
            )
        for k, box in enumerate(s.boxes):
            name = f"/obstacles/box_{k}"
            wxyz = _wxyz(box[6:15])
            self._add(
                name,
                sc.add_box(
                    name, color=_OBSTACLE, dimensions=2 * box[3:6], opacity=0.45, position=box[:3], wxyz=wxyz
                ),
            )
        for k, cyl in enumerate(s.cylinders):
            name = f"/obstacles/cylinder_{k}"
            self._add(
                name,
                sc.add_cylinder(
                    name,
                    radius=float(cyl[3]),
                    height=float(2 * cyl[4]),
                    color=_OBSTACLE,
                    opacity=0.45,
                    position=cyl[:3],
                    wxyz=_wxyz(cyl[5:14]),
                ),
            )
        centre = (lo + hi) / 2
        radius = float(np.linalg.norm(hi - lo)) / 2
        self.server.initial_camera.look_at = tuple(centre)
        self.server.initial_camera.position = tuple(centre + radius * np.array([1.1, -1.5, 0.8]))

        gui = self.server.gui
        n = s.frames
        self.slider = gui.add_slider("frame", min=0, max=max(n - 1, 0), step=1, initial_value=0)
        self.playing = gui.add_checkbox("play", initial_value=False)
        self.fps = gui.add_number("fps", initial_value=float(fps), min=0.5, max=120.0, step=0.5)
        self._time = gui.add_text("time", initial_value=self._time_text(0), disabled=True)

        @self.slider.on_update
        def _(_event) -> None:
            self._show(int(self.slider.value))

    def _time_text(self, i: int) -> str:
        n = self.scene.frames
        if self.scene.times is None:
            return f"{i + 1}/{n}"
        return f"t = {self.scene.times[i]:.2f} s ({i + 1}/{n})"

    def _show(self, i: int) -> None:
        with self._lock:
            self._frame = i
            links = self.scene.links[i]
            for k in self._link_pairs:
                a, b = links[k], links[k + 1]
                d = (b - a) / np.linalg.norm(b - a)
                h = self.nodes[f"/arm/link_{k}"]
                h.position = (a + b) / 2
                h.wxyz = _quat_z_to(d)
            for k in range(links.shape[0] - 1):
                self.nodes[f"/arm/joint_{k}"].position = links[k]
            self.nodes["/arm/ee"].position = links[-1]
            self._time.value = self._time_text(i)

    def _play_loop(self) -> None:
        while not self._closed.is_set():
            fps = max(float(self.fps.value), 0.5)
            if self.playing.value and self.scene.frames > 1:
                self.slider.value = (int(self.slider.value) + 1) % self.scene.frames  # → _show
            self._closed.wait(1.0 / fps)

    # ------------------------------------------------------------------ public

    @property
    def url(self) -> str:
        host = "localhost" if self.host in ("0.0.0.0", "::", "127.0.0.1") else self.host
        return f"http://{host}:{self.port}"

    @property
    def frame(self) -> int:
        """The configuration shown now (index into the joint path)."""
        return self._frame

    def set_frame(self, i: int) -> None:
        """Show configuration ``i`` (negative indices count from the end)."""
        n = self.scene.frames
        if not isinstance(i, int | np.integer) or not -n <= i < n:
            raise ConfigError(f"frame must be an integer in [{-n}, {n - 1}], got {i!r}")
        i = int(i) % n
        self.slider.value = i
        self._show(i)  # also when the slider already held i

    def node_names(self) -> tuple[str, ...]:
        """Names of every scene node this viewer added, sorted."""
        return tuple(sorted(self.nodes))

    @property
    def closed(self) -> bool:
        return self._closed.is_set()

    def close(self) -> None:
        """Stop playback and the server; calling it twice is harmless."""
        if self._closed.is_set():
            return
        self._closed.set()
        self._player.join(timeout=2.0)
        self.server.stop()

    def wait(self) -> None:
        """Block until Ctrl-C (or :meth:`close` from another thread), then close."""
        with contextlib.suppress(KeyboardInterrupt):
            while not self._closed.wait(0.5):
                pass
        self.close()

    def __enter__(self) -> PlanViewer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self.closed else self.url
        return f"PlanViewer({self.robot.name!r}, frames={self.scene.frames}, {state})"


def _wxyz(rotation: np.ndarray) -> tuple[float, float, float, float]:
    """A row-major rotation (9,) as viser's quaternion (w, x, y, z)."""
    x, y, z, w = quaternion_from_rotation(rotation)
    return (float(w), float(x), float(y), float(z))


def _check_host(host) -> None:
    """Refuse, before anything starts, a host the viewer cannot listen on (which viser would retry
    without end): an IP address of this machine or ``"localhost"``, bindable now."""
    import ipaddress
    import socket

    if not isinstance(host, str) or not host:
        raise ConfigError(f"host must be an IP address of this machine or 'localhost', got {host!r}")
    if host != "localhost":
        try:
            ipaddress.ip_address(host)
        except ValueError as exc:
            raise ConfigError(
                f"host must be an IP address of this machine ('127.0.0.1', '0.0.0.0', '::1') or 'localhost', "
                f"got {host!r}"
            ) from exc
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    try:
        with socket.socket(family, socket.SOCK_STREAM) as s:
            s.bind((host, 0))
    except OSError as exc:
        raise ConfigError(
            f"the viewer cannot listen on host {host!r} ({exc.strerror or exc}); give an address of this machine"
        ) from exc


def show_plan(
    robot: Robot,
    joints: Any,
    *,
    waypoints: Any = None,
    spheres: Any = None,
    boxes: Any = None,
    times: Any = None,
    cylinders: Any = None,
    scene: Any = None,
    host: str = "127.0.0.1",
    port: int = 8080,
    fps: float = 10.0,
    block: bool = True,
) -> PlanViewer:
    """Serve an interactive 3-D view of ``robot`` along the joint path ``joints`` (open ``viewer.url``).

    Args:
        robot: the robot (``kinlearn.load_robot(name)``).
        joints: ``(N, dof)`` joint path (rad); the slider steps through its rows.
        waypoints: ``(M, 3)`` points to mark (e.g. a plan's ``waypoints``), metres.
        spheres: ``(K, 4)`` obstacle spheres ``[x, y, z, r]``; boxes: ``(B, 6)`` ``[centre, half extents]``
            or ``(B, 15)`` (with a rotation); cylinders: ``(C, 14)``; or all of them as ``scene``, a
            :class:`~kinlearn.collision.Scene`.
        times: ``(N,)`` time stamps (s) shown beside the slider, e.g. a timed trajectory's ``t``.
        host, port: where to listen (localhost by default; ``"0.0.0.0"`` to serve other machines).
            If the port is taken, viser takes the next free one: read ``viewer.port``.
        fps: playback speed in configurations per second (adjustable in the GUI).
        block: wait until Ctrl-C and close before returning; ``False`` returns the running viewer.

    Raises:
        ShapeError, NonFiniteError, ConfigError: malformed inputs. MissingDependencyError: no viser.
    """
    port = as_int(port, "port", minimum=1, maximum=65535)
    _check_host(host)
    if not (isinstance(fps, int | float) and 0.5 <= fps <= 120):
        raise ConfigError(f"fps must be in [0.5, 120], got {fps!r}")
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
    viewer = PlanViewer(robot, scene, host, port, fps)
    if block:
        print(f"kinlearn viewer: open {viewer.url} in a browser (Ctrl-C to stop)")
        viewer.wait()
    return viewer
