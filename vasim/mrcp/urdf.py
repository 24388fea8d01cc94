"""URDF generated from a DH table, with convex-hull collision shapes built by trimesh.

Each link ``k`` (0 = base .. n) gets the convex hull of spheres (radius from the robot file)
at its key points (:meth:`RobotModel.link_key_points`), in the link's own frame: a smooth
hull of the kind the seed wraps its CAD links in (seed Fig. 3.13, "RS"). A fixed ``tcp`` link
carries the TCP. The files go to a cache folder keyed by the model's content (nothing is
downloaded; the same robot is written once per machine).

Example:
    >>> from vasim.mrcp.dh import load_robot
    >>> path = write_urdf(load_robot("rx60b"))
    >>> path.name, path.is_file()
    ('rx60b.urdf', True)
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import threading
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np
import trimesh

from vasim.core.geometry import euler_xyz_from_matrix
from vasim.mrcp.dh import RobotModel, joint_origin

_SPHERE = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
#: Part of every :func:`model_key`: bump it whenever the generated geometry or URDF text
#: changes (icosphere, hull construction, XML), so cached files of the old generator are
#: never reused.
GENERATOR_VERSION = 2
#: Serialises writers within one process (threads); across processes the unique temporary
#: names and atomic renames keep every visible file complete.
_WRITE_LOCK = threading.Lock()


def cache_dir() -> Path:
    """Where generated URDFs live: ``$VASIM_CACHE/urdf`` or ``<tmp>/vasim-cache/urdf``."""
    root = os.environ.get("VASIM_CACHE") or os.path.join(tempfile.gettempdir(), "vasim-cache")
    return Path(root) / "urdf"


def link_hull(robot: RobotModel, k: int) -> trimesh.Trimesh:
    """Convex hull (link ``k`` frame, metres) of spheres at the link's key points.

    The sphere is an icosphere scaled so that its faces lie *outside* the true sphere
    (circumscribed), so the hull contains every swept sphere.
    """
    pts, unit, scale = link_sweep(robot, k)
    cloud = (pts[:, None, :] + (unit * scale)[None, :, :]).reshape(-1, 3)
    return trimesh.convex.convex_hull(cloud)


def link_sweep(robot: RobotModel, k: int) -> tuple[np.ndarray, np.ndarray, float]:
    """The two parts of link ``k``'s hull ``conv(P) ⊕ conv(scale * S)``: the key points
    ``P`` ``(m, 3)`` (link frame), the unit icosphere's vertices ``S`` ``(162, 3)`` and the
    scale that circumscribes it about the link's sphere radius ``r`` (its faces at ``r``).
    """
    radius = robot.links[k].radius if robot.links else 0.01
    # the inscribed radius of a subdivided icosphere: the smallest face-plane distance
    normals = _SPHERE.face_normals
    centroids = _SPHERE.triangles_center
    inradius = float(np.min(np.einsum("ij,ij->i", normals, centroids)))
    return robot.link_key_points(k), np.asarray(_SPHERE.vertices), radius / inradius


_HULLS: dict[str, tuple[trimesh.Trimesh, ...]] = {}


def link_hulls(robot: RobotModel) -> tuple[trimesh.Trimesh, ...]:
    """Hulls of links ``0..n`` (cached per robot content; do not modify them)."""
    key = model_key(robot)
    if key not in _HULLS:
        _HULLS[key] = tuple(link_hull(robot, k) for k in range(robot.n_joints + 1))
    return _HULLS[key]


def model_key(robot: RobotModel) -> str:
    """A short content hash of the model (DH table, TCP, link geometry); computed once per
    model object (the model is frozen)."""
    key = robot.__dict__.get("_content_key")
    if key is None:
        h = hashlib.sha256()
        h.update(repr((GENERATOR_VERSION, robot.name, robot.joints, robot.links,
                       tuple(robot.tcp))).encode())
        key = h.hexdigest()[:16]
        object.__setattr__(robot, "_content_key", key)
    return key


def _origin_xml(t: np.ndarray) -> str:
    rpy = euler_xyz_from_matrix(t[:3, :3])
    xyz = " ".join(repr(float(v)) for v in t[:3, 3])
    return f'<origin xyz="{xyz}" rpy="{" ".join(repr(float(v)) for v in rpy)}"/>'


def _link_xml(name: str, mesh: str | None) -> str:
    inertial = ('<inertial><origin xyz="0 0 0" rpy="0 0 0"/><mass value="1.0"/>'
                '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>'
                '</inertial>')
    if mesh is None:
        return f'  <link name="{name}">{inertial}</link>\n'
    geom = f'<geometry><mesh filename="{mesh}"/></geometry>'
    return (f'  <link name="{name}">{inertial}\n'
            f'    <visual><origin xyz="0 0 0" rpy="0 0 0"/>{geom}</visual>\n'
            f'    <collision><origin xyz="0 0 0" rpy="0 0 0"/>{geom}</collision>\n'
            f'  </link>\n')


def urdf_text(robot: RobotModel) -> str:
    """The URDF document (mesh files named ``link{k}.obj`` beside it)."""
    n = robot.n_joints
    parts = [f'<?xml version="1.0"?>\n<robot name="{robot.name}">\n',
             _link_xml("link0", "link0.obj")]
    for i, joint in enumerate(robot.joints, start=1):
        parts.append(_link_xml(f"link{i}", f"link{i}.obj"))
        parts.append(
            f'  <joint name="joint{i}" type="revolute"><parent link="link{i - 1}"/>'
            f'<child link="link{i}"/>{_origin_xml(joint_origin(joint))}<axis xyz="0 0 1"/>'
            f'<limit lower="{joint.lower!r}" upper="{joint.upper!r}" effort="100" '
            f'velocity="{joint.max_velocity!r}"/></joint>\n')
    tcp = np.eye(4)
    tcp[:3, 3] = robot.tcp
    parts.append(_link_xml("tcp", None))
    parts.append(f'  <joint name="tcp_joint" type="fixed"><parent link="link{n}"/>'
                 f'<child link="tcp"/>{_origin_xml(tcp)}</joint>\n</robot>\n')
    return "".join(parts)


def _atomic_write(path: Path, write: Callable[[Path], object]) -> None:
    """Writes through a temporary file unique to this call (``mkstemp`` in the same
    folder: threads of one process used to share a pid-only name and collide) and renames
    it over ``path`` atomically."""
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_urdf(robot: RobotModel, folder: Path | None = None) -> Path:
    """Writes the URDF and its link hulls (once per content) and returns the URDF path.

    The cache is complete only when the URDF *and* every ``link{k}.obj`` exist: missing
    files (an interrupted or partly cleaned cache) are written again, the URDF last.
    """
    folder = folder or cache_dir() / f"{robot.name}-{model_key(robot)}"
    path = folder / f"{robot.name}.urdf"
    meshes = [folder / f"link{k}.obj" for k in range(robot.n_joints + 1)]
    if path.is_file() and all(m.is_file() for m in meshes):
        return path
    with _WRITE_LOCK:
        folder.mkdir(parents=True, exist_ok=True)
        for mesh_path, hull in zip(meshes, link_hulls(robot), strict=True):
            if not mesh_path.is_file():
                _atomic_write(mesh_path, partial(hull.export, file_type="obj"))
        if not path.is_file():
            text = urdf_text(robot)
            _atomic_write(path, lambda t: t.write_text(text, encoding="utf-8"))
    return path
