"""Tasks of the virtual abdomen: trajectory following and point targeting (spec/study.md §1).

Example:
    >>> from vasim.tasks import trajectory_task, point_task, TRAJECTORY_VARIANTS
    >>> [trajectory_task(v).n_points for v in range(TRAJECTORY_VARIANTS)] == [30] * 7
    True
    >>> point_task().kind
    'point'
"""

from __future__ import annotations

from vasim.tasks.base import DEFAULT_REACH_RADIUS as DEFAULT_REACH_RADIUS
from vasim.tasks.base import WORKSPACE_CENTRE as WORKSPACE_CENTRE
from vasim.tasks.base import WORKSPACE_MAX as WORKSPACE_MAX
from vasim.tasks.base import WORKSPACE_MIN as WORKSPACE_MIN
from vasim.tasks.base import Task as Task
from vasim.tasks.base import TaskKind as TaskKind
from vasim.tasks.point import point_task as point_task
from vasim.tasks.trajectory import TRAJECTORY_VARIANTS as TRAJECTORY_VARIANTS
from vasim.tasks.trajectory import VARIANT_NAMES as VARIANT_NAMES
from vasim.tasks.trajectory import trajectory_task as trajectory_task

__all__ = [
    "DEFAULT_REACH_RADIUS",
    "TRAJECTORY_VARIANTS",
    "VARIANT_NAMES",
    "WORKSPACE_CENTRE",
    "WORKSPACE_MAX",
    "WORKSPACE_MIN",
    "Task",
    "TaskKind",
    "point_task",
    "trajectory_task",
]
