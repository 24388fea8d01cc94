"""The robot world over pybullet, one name for both halves (kept for the existing imports):
arms in :mod:`vasim.mrcp.arm` (:class:`PybulletArm`, kinematics and IK) and stations in
:mod:`vasim.mrcp.world` (:class:`PybulletWorld`, proximity and collisions). Only those two
modules import pybullet (issue #14 item 4: the ~1,000-line module split by job).

Example:
    >>> from vasim.mrcp.backend import PybulletArm, PybulletWorld
    >>> PybulletArm.__module__, PybulletWorld.__module__
    ('vasim.mrcp.arm', 'vasim.mrcp.world')
"""

from __future__ import annotations

from vasim.mrcp.arm import PybulletArm, pose_matrix, rotation_error
from vasim.mrcp.world import (
    COMPILED_TOLERANCE,
    DIRECTION_ITERATIONS,
    HULL_MARGIN,
    REFINE_BELOW,
    PybulletWorld,
)

__all__ = ["COMPILED_TOLERANCE", "DIRECTION_ITERATIONS", "HULL_MARGIN", "REFINE_BELOW",
           "PybulletArm", "PybulletWorld", "pose_matrix", "rotation_error"]
