"""What defines a viewer trial's condition, and how it is named and stored (issue #20 §3, §4).

* **Edited schemas.** The experimenter's live f5PL editing makes a schema that is not the
  shipped one. It is stored under :func:`edited_schema_name` — the shipped name, the
  marker ``.edited-`` and the first 10 hex digits of the SHA-256 of its full TOML (written
  with the shipped name, so the hash depends on the parameters only) — beside that full
  TOML (``trials.schema_toml``). A report groups trials by schema name, so it never pools an
  edited schema with the shipped one unless asked (by naming both).
* **The viewer's part of the condition** (:func:`viewer_condition`): the input device, the
  instrument's mapping, the endoscope's optics and whether Mag drives the endoscope; stored
  in the trial's config under ``"viewer"``. Per-client view preferences (the experimenter's
  free camera, audio on/off) are not part of it and never change it.
"""

from __future__ import annotations

import hashlib
from dataclasses import replace
from typing import Any

from vasim.fixtures.schema import Schema, dumps_schema

EDITED_MARK = ".edited-"
"""Separates the shipped name from the parameter hash in an edited schema's name."""


def shipped_name(name: str) -> str:
    """The shipped schema's name of a (possibly edited) schema name.

    >>> shipped_name("trajectory_following.edited-0123456789"), shipped_name("vg")
    ('trajectory_following', 'vg')
    """
    return name.split(EDITED_MARK, 1)[0]


def edited_schema_name(schema: Schema, shipped: str | None = None) -> str:
    """The name an edited ``schema`` is stored under: ``<shipped>.edited-<hash>``.

    Args:
        schema: the edited schema (its own name may be the shipped one or an edited one).
        shipped: the shipped schema's name (default: derived from ``schema.name``).

    Returns:
        ``<shipped>.edited-<h>``, ``h`` the first 10 hex digits of the SHA-256 of
        ``dumps_schema`` of the schema renamed to ``<shipped>``: equal parameters give the
        same name, any changed parameter (to the last digit ``dumps_schema`` writes) another.
    """
    base = shipped_name(shipped if shipped is not None else schema.name)
    text = dumps_schema(replace(schema, name=base))
    return f"{base}{EDITED_MARK}{hashlib.sha256(text.encode()).hexdigest()[:10]}"


def named_edit(edited: Schema, shipped: Schema) -> Schema:
    """``edited`` under the name it is stored with.

    **Decision**: an edit that leaves every parameter as shipped (e.g. edited back) keeps
    the shipped name, because its trials ran the shipped condition exactly.
    """
    if dumps_schema(replace(edited, name=shipped.name)) == dumps_schema(shipped):
        return replace(edited, name=shipped.name)
    return replace(edited, name=edited_schema_name(edited, shipped.name))


def viewer_condition(*, input_kind: str, mapping: Any | None, optics_deg: float,
                     mag_camera: bool) -> dict[str, Any]:
    """The viewer's part of a trial's condition, as stored in its config (``"viewer"``).

    Args:
        input_kind: who moved the tool (``controller.INPUTS``).
        mapping: the instrument's ``InputMapping`` (laparoscopic input), else None.
        optics_deg: the endoscope's optics angle [deg] (0 or 30).
        mag_camera: True when the schema's Mag fixture drives the endoscope.
    """
    out: dict[str, Any] = {"input": input_kind, "optics_deg": float(optics_deg),
                           "mag_camera": bool(mag_camera)}
    if mapping is not None:
        out["input_mapping"] = {"fulcrum_effect": bool(mapping.fulcrum_effect),
                                "sensitivity": float(mapping.sensitivity)}
    return out


__all__ = ["EDITED_MARK", "edited_schema_name", "named_edit", "shipped_name",
           "viewer_condition"]
