"""Suitability indices of the MRCP kernel: one :class:`Index` protocol, a registry, plug-ins.

Importing this package registers every built-in index in :data:`INDICES`:
``rj``, ``theta``, ``psi``, ``cr``, ``cone``, ``visibility``, ``force_torque`` and the analysis
measures ``manipulability``, ``order_independent_manipulability``, ``sigma_min``,
``reciprocal_condition_number``, ``isotropy``.
"""

from __future__ import annotations

from vasim.mrcp.indices import collision as collision
from vasim.mrcp.indices import cone as cone
from vasim.mrcp.indices import dexterity as dexterity
from vasim.mrcp.indices import force_torque as force_torque
from vasim.mrcp.indices import joint_limits as joint_limits
from vasim.mrcp.indices import visibility as visibility
from vasim.mrcp.indices.base import INDICES as INDICES
from vasim.mrcp.indices.base import EvalContext as EvalContext
from vasim.mrcp.indices.base import GroupIndex as GroupIndex
from vasim.mrcp.indices.base import Index as Index
from vasim.mrcp.indices.base import IndexRegistry as IndexRegistry
from vasim.mrcp.indices.base import Wrench as Wrench
