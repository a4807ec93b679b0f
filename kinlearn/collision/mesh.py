"""An independent check of configurations and paths against the robot's own collision meshes (coal).

The planners check with spheres (:class:`~kinlearn.collision.BodySpheres`); this module asks the
question again of the geometry the URDF itself gives, with coal (which ships with pinocchio): each
link's ``<collision>`` meshes and primitives, as pinocchio places them, against the scene's
primitives as coal shapes (the floor a half-space, which the base and what no joint raises or lowers
are exempt from, as in the sphere body) and against each other (link pairs two or more apart, less the pairs the robot's sphere model
leaves out: an SRDF's, or pairs touching in every configuration). It is slower and does not look
between the configurations it is given: :func:`mesh_check` walks each path segment in steps of at
most ``max_step`` rad per joint.

A plan called collision-free by the sphere check should be free here too: :func:`judge_meshes` says
which plans are, for a user who asks (and ``benchmarks/onboard.py`` counts those that are not).
"""

from __future__ import annotations

import itertools
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import torch

from ..body.robot import Robot, _example_robot_data_dir
from ..errors import MissingDependencyError, RobotDescriptionError, ShapeError
from .geometry import Box, Cylinder, Sphere

__all__ = ["MeshBody", "chain_link_of", "judge_meshes", "mesh_check"]


def _modules():
    try:
        import coal
        import pinocchio as pin
    except ImportError as exc:  # pragma: no cover - both ship with `pin`, a dependency
        raise MissingDependencyError("the mesh check needs pinocchio and coal: pip install pin") from exc
    return pin, coal


def _package_dirs(extra) -> list[str]:
    dirs = [str(d) for d in extra]
    try:
        dirs.append(str(_example_robot_data_dir().parent.parent))  # .../share, holding example-robot-data
    except RobotDescriptionError:
        pass
    return dirs


def _excluded_pairs(robot: Robot) -> set[tuple[int, int]]:
    """The link pairs the robot's sphere model leaves out of self-collision (its JSON's
    ``excluded_link_pairs``), if it has one."""
    import json

    own = getattr(robot, "sphere_urdf", None)
    path = None
    if own is not None and Path(own).suffix.lower() == ".json":
        path = Path(own)
    else:
        from .body import _model_path

        p = _model_path(robot)
        path = p if p.is_file() else None
    if path is None:
        return set()
    rule = json.loads(path.read_text()).get("self_collision", {})
    pairs = rule.get("excluded_link_pairs", [])
    why = rule.get("excluded_because", ["given"] * len(pairs))
    # pairs left out because the meshes never met in sampled configurations stay checked here: this is the
    # check that says whether they ever do
    return {
        tuple(sorted(int(v) for v in p))
        for p, w in zip(pairs, why, strict=False)
        if not w.startswith("never")
    }


def chain_link_of(robot: Robot, root: ET.Element, link: str) -> int | None:
    """The chain link (0 = base) a URDF link is carried with, up through fixed joints and joints off the
    chain (None: above the base)."""
    joints_by_child = {el.find("child").get("link"): el for el in root.findall("joint")}
    index = {j.name: k + 1 for k, j in enumerate(robot.joints)}
    first = next(el for el in root.findall("joint") if el.get("name") == robot.joints[0].name)
    base = first.find("parent").get("link")
    cur = link
    while True:
        if cur == base:
            return 0
        el = joints_by_child.get(cur)
        if el is None:
            return None
        if el.get("name") in index:
            return index[el.get("name")]
        cur = el.find("parent").get("link")  # fixed, or moving off the chain: its spheres go up the tree


class MeshBody:
    """The robot's URDF collision geometry in coal, posed by pinocchio from kinlearn's joint vector.

    ``urdf``: the file whose ``<collision>`` elements are the judge (default: the robot's own URDF).
    ``package_dirs``: folders where ``package://`` meshes are looked for (example-robot-data's is
    added). ``excluded_link_pairs``: chain-link pairs (0 = base) never checked against each other
    (default: the robot's sphere model's). Joints of the URDF that are not on kinlearn's chain (a
    gripper) stay at zero (or their nearest limit).
    """

    def __init__(
        self,
        robot: Robot,
        urdf: str | Path | None = None,
        package_dirs: tuple = (),
        excluded_link_pairs=None,
        self_collision: bool = True,
    ):
        pin, coal = _modules()
        path = Path(urdf) if urdf is not None else robot.urdf_path
        if path is None:
            raise RobotDescriptionError(f"{robot.name} has no URDF file to read collision meshes from")
        self.robot = robot
        self.model = pin.buildModelFromUrdf(str(path))
        try:
            self.geom = pin.buildGeomFromUrdf(
                self.model,
                str(path),
                pin.GeometryType.COLLISION,
                package_dirs=_package_dirs((*package_dirs, path.parent)),
            )
        except (RuntimeError, ValueError) as exc:
            raise RobotDescriptionError(
                f"pinocchio could not read the collision geometry of {path}: {exc}"
            ) from exc
        if len(self.geom.geometryObjects) == 0:
            raise RobotDescriptionError(f"{path} has no <collision> geometry to check against")
        self.data = self.model.createData()
        self.gdata = pin.GeometryData(self.geom)
        root = ET.fromstring(path.read_bytes())
        self.link = np.array(
            [
                -1 if (k := chain_link_of(robot, root, self.model.frames[o.parentFrame].name)) is None else k
                for o in self.geom.geometryObjects
            ]
        )
        from .body import floor_applies

        # kinlearn's joint vector → pinocchio's configuration
        q0 = pin.neutral(self.model)
        lo, hi = self.model.lowerPositionLimit, self.model.upperPositionLimit
        q0 = np.where(np.isfinite(lo) & np.isfinite(hi), np.clip(q0, lo, hi), q0)
        self.q0 = q0
        self.slots = []
        for j in robot.joints:
            if not self.model.existJointName(j.name):
                raise RobotDescriptionError(f"{path} has no joint {j.name!r}, a joint of {robot.name}")
            jm = self.model.joints[self.model.getJointId(j.name)]
            self.slots.append((jm.idx_q, jm.nq))
        excluded = _excluded_pairs(robot) if excluded_link_pairs is None else {
            tuple(sorted(int(v) for v in p)) for p in excluded_link_pairs
        }  # fmt: skip
        n = len(self.link)
        self.self_pairs = [
            (a, b)
            for a in range(n)
            for b in range(a + 1, n)
            if self_collision
            and self.link[a] >= 0
            and self.link[b] >= 0
            and abs(self.link[a] - self.link[b]) >= 2
            and (min(self.link[a], self.link[b]), max(self.link[a], self.link[b])) not in excluded
        ]
        self._req = coal.CollisionRequest()
        self._res = coal.CollisionResult()
        # each geometry's bounding sphere in its own frame, for a cheap cull
        self.bound = []
        for o in self.geom.geometryObjects:
            g = o.geometry
            g.computeLocalAABB()
            c = 0.5 * (np.asarray(g.aabb_local.min_) + np.asarray(g.aabb_local.max_))
            r = 0.5 * float(np.linalg.norm(np.asarray(g.aabb_local.max_) - np.asarray(g.aabb_local.min_)))
            self.bound.append((c, r))
        objs = self.geom.geometryObjects
        self.on_floor = floor_applies(  # as the sphere body: not what rests on the mount
            robot,
            np.maximum(self.link, 0),
            np.array(
                [
                    o.placement.rotation @ c + o.placement.translation
                    for o, (c, _) in zip(objs, self.bound, strict=True)
                ]
            ),
            np.array([r for _, r in self.bound]),
        )

    def touching_link_pairs(self, q) -> np.ndarray:
        """``(N, P)`` bool over :attr:`self_pairs`' chain-link pairs (``self.pair_links``): which touch in each
        configuration ``q (N, dof)``, by the meshes."""
        pin, coal = _modules()
        q = np.asarray(q, dtype=np.float64).reshape(-1, self.robot.dof)
        links = sorted({(int(self.link[a]), int(self.link[b])) for a, b in self.self_pairs})
        self.pair_links = links
        col = {lk: i for i, lk in enumerate(links)}
        out = np.zeros((len(q), len(links)), dtype=bool)
        objs = self.geom.geometryObjects
        for n, qn in enumerate(q):
            pin.updateGeometryPlacements(self.model, self.data, self.geom, self.gdata, self.configuration(qn))
            places = self.gdata.oMg
            for a, b in self.self_pairs:
                k = col[(int(self.link[a]), int(self.link[b]))]
                if out[n, k]:
                    continue
                Ma, Mb = places[a], places[b]
                ca = Ma.rotation @ self.bound[a][0] + Ma.translation
                cb = Mb.rotation @ self.bound[b][0] + Mb.translation
                if np.linalg.norm(ca - cb) > self.bound[a][1] + self.bound[b][1]:
                    continue
                self._res.clear()
                out[n, k] = coal.collide(
                    objs[a].geometry, coal.Transform3s(Ma.rotation, Ma.translation),
                    objs[b].geometry, coal.Transform3s(Mb.rotation, Mb.translation),
                    self._req, self._res,
                )  # fmt: skip
        return out

    def configuration(self, q: np.ndarray) -> np.ndarray:
        """Pinocchio's configuration for kinlearn's joints ``q (dof,)``."""
        out = self.q0.copy()
        for (i, nq), v in zip(self.slots, q, strict=True):
            if nq == 2:  # a continuous joint: (cos, sin)
                out[i], out[i + 1] = math.cos(v), math.sin(v)
            else:
                out[i] = v
        return out

    def _obstacles(self, scene):
        _, coal = _modules()
        out = []
        for p in scene.primitives():
            if type(p).__name__ == "Plane":
                continue  # the floor: checked as the scene's floor (the base is exempt from it)
            if isinstance(p, Sphere):
                g, R, t, r = coal.Sphere(float(p.radius)), np.eye(3), np.asarray(p.centre), float(p.radius)
            elif isinstance(p, Box):
                h = np.asarray(p.half_extents, dtype=np.float64)
                g, R, t = coal.Box(*(2.0 * h)), np.asarray(p.rotation).reshape(3, 3), np.asarray(p.centre)
                r = float(np.linalg.norm(h))
            elif isinstance(p, Cylinder):
                g = coal.Cylinder(float(p.radius), 2.0 * float(p.half_length))
                R, t = np.asarray(p.rotation).reshape(3, 3), np.asarray(p.centre)
                r = float(math.hypot(p.radius, p.half_length))
            else:  # pragma: no cover - a kind added to the scenes later
                raise ShapeError(f"the mesh check does not know obstacles of kind {type(p).__name__}")
            tf = coal.Transform3s()
            tf.setRotation(np.asarray(R, dtype=np.float64))
            tf.setTranslation(np.asarray(t, dtype=np.float64))
            out.append((g, tf, np.asarray(t, dtype=np.float64), r))
        return out

    def collides(self, q, scene=None) -> np.ndarray:
        """``(N,)`` bool: where configurations ``q (N, dof)`` put the meshes into the scene (its
        primitives and floor) or into each other."""
        pin, coal = _modules()
        q = np.asarray(q, dtype=np.float64).reshape(-1, self.robot.dof)
        obstacles = self._obstacles(scene) if scene is not None else []
        floor = None
        if scene is not None and scene.floor is not None:
            floor = float(torch.as_tensor(scene.floor).reshape(-1)[0])
        out = np.zeros(len(q), dtype=bool)
        objs = self.geom.geometryObjects
        for n, qn in enumerate(q):
            pin.updateGeometryPlacements(self.model, self.data, self.geom, self.gdata, self.configuration(qn))
            places = self.gdata.oMg
            hit = False
            centres = []
            for k, o in enumerate(objs):
                M = places[k]
                c = M.rotation @ self.bound[k][0] + M.translation
                centres.append(c)
                if self.link[k] < 0:
                    continue
                tf = coal.Transform3s(M.rotation, M.translation)
                if floor is not None and self.on_floor[k] and c[2] - self.bound[k][1] < floor:
                    hs = coal.Halfspace(np.array([0.0, 0.0, 1.0]), floor)
                    self._res.clear()
                    if coal.collide(o.geometry, tf, hs, coal.Transform3s(), self._req, self._res):
                        hit = True
                        break
                for g, otf, oc, orad in obstacles:
                    if np.linalg.norm(c - oc) > self.bound[k][1] + orad:
                        continue
                    self._res.clear()
                    if coal.collide(o.geometry, tf, g, otf, self._req, self._res):
                        hit = True
                        break
                if hit:
                    break
            if not hit:
                for a, b in self.self_pairs:
                    if np.linalg.norm(centres[a] - centres[b]) > self.bound[a][1] + self.bound[b][1]:
                        continue
                    Ma, Mb = places[a], places[b]
                    self._res.clear()
                    if coal.collide(
                        objs[a].geometry, coal.Transform3s(Ma.rotation, Ma.translation),
                        objs[b].geometry, coal.Transform3s(Mb.rotation, Mb.translation),
                        self._req, self._res,
                    ):  # fmt: skip
                        hit = True
                        break
            out[n] = hit
        return out


def mesh_check(body: MeshBody, paths, scene=None, max_step: float = 0.01) -> np.ndarray:
    """``(...)`` bool: whether each joint path ``paths (..., T+1, dof)`` is free of collision with the
    robot's meshes (``body``) in ``scene`` (one scene for every path), checked at its configurations and
    between them in steps of at most ``max_step`` rad per joint (straight joint lines)."""
    p = np.asarray(paths.detach().cpu().double() if isinstance(paths, torch.Tensor) else paths, np.float64)
    if p.ndim < 2 or p.shape[-1] != body.robot.dof:
        raise ShapeError(f"paths must have shape (..., T+1, {body.robot.dof}), got {p.shape}")
    if not max_step > 0:
        raise ShapeError(f"max_step must be > 0 rad, got {max_step!r}")
    flat = p.reshape(-1, *p.shape[-2:])
    free = np.ones(len(flat), dtype=bool)
    for i, path in enumerate(flat):
        dense = [path[:1]]
        for a, b in itertools.pairwise(path):
            n = max(1, math.ceil(float(np.abs(b - a).max()) / max_step))
            s = np.arange(1, n + 1)[:, None] / n
            dense.append(a + s * (b - a))
        free[i] = not body.collides(np.concatenate(dense), scene).any()
    return free.reshape(p.shape[:-2])


def judge_meshes(plan, scene=None, body: MeshBody | None = None, max_step: float = 0.01) -> np.ndarray:
    """``(...)`` bool: for a :class:`~kinlearn.planning.plan.Plan` (or a batch of them), whether each plan
    it calls successful is also free under the robot's collision meshes (:func:`mesh_check`): the exact,
    slower second opinion on what the sphere check passed. A plan that did not succeed is False. ``scene``:
    the obstacles (default: the scene the plan records it was planned among, where it records one)."""
    if scene is None:
        scene = getattr(plan, "scene", None)
    if body is None:
        from ..body.robot import load_robot

        body = MeshBody(load_robot(plan.robot))
    joints = plan.joints
    ok = torch.as_tensor(plan.success).cpu().numpy().astype(bool)
    out = np.zeros(ok.shape, dtype=bool)
    flat_ok = ok.reshape(-1)
    flat_j = joints.reshape(-1, *joints.shape[-2:]) if isinstance(joints, torch.Tensor) else joints
    flat_out = out.reshape(-1)
    batched = scene is not None and len(scene.batch_shape) > 0
    scenes = scene.expand(*ok.shape).reshape(max(1, ok.size)) if batched else None
    for i in np.flatnonzero(flat_ok):
        flat_out[i] = bool(mesh_check(body, flat_j[i], scenes[int(i)] if batched else scene, max_step))
    return out
