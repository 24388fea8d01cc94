"""Stations for the scenarios: RX60B robots in pybullet, plus *sensing* bodies that are seen
by distance queries but never collide (a camera's view cone).

The visibility index (spec §4, seed 3.6.1) measures the distance from a robot to the
camera's view cone, a body of the proximity world; but a robot entering the cone occludes,
it does not collide, so the cone must not count in ``in_collision`` (RSel's safety stop).
:class:`Station` composes two :class:`~vasim.mrcp.backend.PybulletWorld` instances posed
identically: the *physical* one (robots, obstacles: collisions and distances) and the
*sensing* one (the same robots plus the view cones: distances only). Both are composed
rather than one patched, so the robot world's files stay untouched (**decision**).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from vasim.mrcp.interfaces import FloatArray, Proximity
from vasim.mrcp.scenarios.base import rx60b_model


def view_cone_vertices(camera: FloatArray, target: FloatArray, radius: float,
                       segments: int = 16) -> FloatArray:
    """Vertices of the camera's view cone on a sphere (``target``, ``radius``): apex at the
    camera, base the circle where the tangent cone meets the sphere's near side (the cone
    stops before the object so the object and its holders' fingers are not inside it).

    Example:
        >>> v = view_cone_vertices(np.zeros(3), np.array([0.0, 1.0, 0.0]), 0.1, 4)
        >>> v.shape, bool(np.allclose(v[0], 0.0)), round(float(v[1:, 1].max()), 3)
        ((5, 3), True, 0.9)
    """
    camera = np.asarray(camera, dtype=float)
    axis = np.asarray(target, dtype=float) - camera
    dist = float(np.linalg.norm(axis))
    if dist <= radius:
        raise ValueError(f"view cone: camera {camera!r} is inside the object's sphere")
    axis /= dist
    depth = dist - radius
    r_base = depth * np.tan(np.arcsin(radius / dist))
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    ang = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    ring = (camera + depth * axis)[None, :] + r_base * (np.cos(ang)[:, None] * u
                                                        + np.sin(ang)[:, None] * v)
    return np.vstack([camera[None, :], ring])


class Station:
    """A :class:`~vasim.mrcp.interfaces.ProximityWorld` over RX60B robots with physical
    obstacles and non-colliding sensing bodies.

    Example:
        >>> st = Station()
        >>> _ = st.add_robot("R0", np.eye(4))
        >>> st.add_sensing_convex("view_cone", view_cone_vertices(
        ...     np.array([0.0, -0.8, 0.0]), np.array([0.3, 0.0, 0.0]), 0.05))
        >>> st.obstacle_names(), st.in_collision("R0")
        (['view_cone'], False)
        >>> st.close()
    """

    def __init__(self) -> None:
        from vasim.mrcp.backend import PybulletWorld

        self.physical = PybulletWorld()
        self.sensing = PybulletWorld()
        self._soft: list[str] = []
        self._model = rx60b_model()

    @property
    def model(self) -> Any:
        return self._model

    # -- building ----------------------------------------------------------------------
    def add_robot(self, name: str, base: FloatArray, q: FloatArray | None = None) -> None:
        """Adds an RX60B at ``base`` (``(4, 4)``), posed at ``q`` (default home)."""
        self.physical.add_robot(name, self._model, base, q)
        self.sensing.add_robot(name, self._model, base, q)

    def add_box(self, name: str, half_extents: FloatArray, position: FloatArray,
                rotation: FloatArray | None = None) -> None:
        self.physical.add_box(name, half_extents, position, rotation)

    def add_sphere(self, name: str, radius: float, position: FloatArray) -> None:
        self.physical.add_sphere(name, radius, position)

    def add_convex(self, name: str, vertices: FloatArray, position: FloatArray | None = None,
                   rotation: FloatArray | None = None) -> None:
        self.physical.add_convex(name, vertices, position, rotation)

    def add_sensing_convex(self, name: str, vertices: FloatArray) -> None:
        """A body seen by distance queries only (never a collision)."""
        self.sensing.add_convex(name, vertices)
        self._soft.append(name)
        for robot in self.physical.robot_names():
            self.sensing.set_configuration(robot, self.physical.configuration(robot))

    def set_obstacle_pose(self, name: str, position: FloatArray,
                          rotation: FloatArray | None = None) -> None:
        world = self.sensing if name in self._soft else self.physical
        world.set_obstacle_pose(name, position, rotation)

    # -- ProximityWorld ----------------------------------------------------------------
    def robot_names(self) -> list[str]:
        return self.physical.robot_names()

    def obstacle_names(self) -> list[str]:
        return [*self.physical.obstacle_names(), *self._soft]

    def set_configuration(self, robot: str, q: FloatArray) -> None:
        self.physical.set_configuration(robot, q)
        if self._soft:
            self.sensing.set_configuration(robot, q)

    def configuration(self, robot: str) -> FloatArray:
        return self.physical.configuration(robot)

    def min_distance(self, a: str, b: str, max_distance: float = 1.0) -> Proximity:
        world = self.sensing if (a in self._soft or b in self._soft) else self.physical
        return world.min_distance(a, b, max_distance)

    def in_collision(self, robot: str) -> bool:
        return self.physical.in_collision(robot)

    def min_distances(self, robot: str, configs: FloatArray, bodies: Sequence[str],
                      max_distance: float = 1.0) -> FloatArray:
        """``(N, B)`` distances from ``robot`` posed at each of ``configs`` to ``bodies``: the
        worlds' batched query (the kernel's indices use it when a world has it), each body
        asked of the world that holds it."""
        qs = np.atleast_2d(np.asarray(configs, dtype=float))
        names = list(bodies)
        out = np.full((qs.shape[0], len(names)), float(max_distance))
        for world, pick in ((self.physical, [i for i, b in enumerate(names)
                                             if b not in self._soft]),
                            (self.sensing, [i for i, b in enumerate(names) if b in self._soft])):
            if pick:
                out[:, pick] = world.min_distances(robot, qs, [names[i] for i in pick],
                                                   max_distance)
        return out

    def close(self) -> None:
        self.physical.close()
        self.sensing.close()
