"""Loading protocol files: TOML text -> validated :class:`Protocol` (unknown keys,
missing fields and bad values are refused with file, field, value and what was expected).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from vasim.core.config import (
    check_array_of_tables,
    check_keys,
    check_table,
    expect,
    parse_toml,
    rewrap,
)
from vasim.core.errors import ConfigError
from vasim.core.resources import available_files, data_file, read_data_file, studies_dir
from vasim.study.protocol.model import Block, Protocol
from vasim.study.protocol.phases import Gate
from vasim.study.protocol.power import power_plan_from_table
from vasim.study.protocol.questionnaires import QuestionItem, Questionnaire

_TOP = ("name", "description", "task", "reach_radius_m", "max_trial_time_s",
        "excessive_force_n", "repeat_timed_out", "path_tolerance_m", "poi_spacing_m",
        "randomisation", "probe", "blocks",
        "questionnaires", "power")
_BLOCK = ("name", "condition", "variants", "repetitions", "probe", "counterbalance",
          "probes_after", "schema", "phase", "delay_days", "gate")
_GATE = ("metrics", "k", "consecutive", "max_trials", "expert_group")
_ITEM = ("id", "type", "prompt", "required", "options", "conditions", "select", "min",
         "max", "anchors", "max_entries", "min_size", "max_length")

_BLOCK_GAIN = ("gain_schedule", "adaptive")
"""Block keys of the fading and adaptive fixtures (issue #18 item 1)."""


def available_protocols() -> tuple[str, ...]:
    """Names of the protocol files shipped in ``protocols/studies/``, sorted."""
    return available_files(studies_dir())


def protocol_path(ref: str | Path) -> Path:
    """The file a protocol reference names: a path, or a name in ``protocols/studies/``.

    Raises:
        ConfigError: if a bare name matches no shipped protocol.
    """
    return data_file(ref, studies_dir(), "protocol")


def load_protocol(ref: str | Path) -> Protocol:
    """Loads and validates a protocol by name (``"vf_learning_curve"``) or path.

    Raises:
        ConfigError: naming the file, the field and the value of the first problem.
    """
    path = protocol_path(ref)
    return parse_protocol(read_data_file(path, "protocol"), source=str(path))


def parse_protocol(text: str, *, source: str = "<string>") -> Protocol:
    """Parses and validates protocol TOML text; ``source`` names it in errors.

    The returned protocol keeps ``text`` (what a session stores).
    """
    return protocol_from_dict(parse_toml(text, file=source, kind="protocol"), text=text,
                              source=source)


def _table(data: Mapping[str, Any], key: str, prefix: str, source: str,
           known: tuple[str, ...]) -> dict[str, Any]:
    path = f"{prefix}.{key}" if prefix else key
    return check_keys(check_table(data.get(key, {}), path, file=source), known, path,
                      file=source)


def _tuple(v: Any) -> Any:
    """TOML arrays become tuples; anything else is passed on for the dataclass to reject."""
    return tuple(v) if isinstance(v, list) else v


def protocol_from_dict(data: Mapping[str, Any], *, text: str | None = None,
                       source: str = "<dict>") -> Protocol:
    """Builds a protocol from parsed TOML (see the module docstring for the layout)."""
    data = check_keys(data, _TOP, "", file=source,
                      required=("name", "description", "task", "blocks"))
    rnd = _table(data, "randomisation", "", source, ("block_order", "variant_order"))
    probe = _table(data, "probe", "", source, ("condition", "variant", "variants"))
    expect("variant" not in probe or "variants" not in probe, probe.get("variants"),
            "either probe.variant (one trajectory for every probe) or probe.variants (a "
            "rotation), not both", file=source, field="probe.variants")
    raw_blocks = check_array_of_tables(data["blocks"], "blocks", file=source)
    blocks = []
    for i, raw in enumerate(raw_blocks):
        path = f"blocks[{i}]"
        check_keys(raw, _BLOCK + _BLOCK_GAIN, path, file=source,
                   required=("name", "condition"))
        # transfer: its own untrained variants
        expect(not ("variants" in probe and raw.get("probe") is True and "variants" in raw
                     and raw.get("phase") != "transfer"), raw.get("variants"),
                "no variants in a probe block: it takes them from probe.variants in rotation "
                "(repetitions = its number of trials)", file=source, field=f"{path}.variants")
        bkw = {k: _tuple(v) for k, v in raw.items()}
        if "gate" in raw:
            gate = _table(raw, "gate", path, source, _GATE)
            check_keys(gate, _GATE, f"{path}.gate", file=source,
                       required=("metrics", "max_trials"))
            try:
                bkw["gate"] = Gate(**{k: _tuple(v) for k, v in gate.items()})
            except ConfigError as exc:
                raise rewrap(exc, f"{path}.gate", source) from exc
        try:
            blocks.append(Block(**bkw))
        except ConfigError as exc:
            raise rewrap(exc, path, source) from exc
    qs = _table(data, "questionnaires", "", source, ("pre", "post"))
    questionnaires = {}
    for qname in ("pre", "post"):
        qpath = f"questionnaires.{qname}"
        q = _table(qs, qname, "questionnaires", source, ("demographics", "items"))
        raw_items = check_array_of_tables(q.get("items", []), f"{qpath}.items", file=source)
        items = []
        for k, raw in enumerate(raw_items):
            path = f"{qpath}.items[{k}]"
            check_keys(raw, _ITEM, path, file=source, required=("id", "type", "prompt"))
            try:
                items.append(QuestionItem(**{key: _tuple(v) for key, v in raw.items()}))
            except ConfigError as exc:
                raise rewrap(exc, path, source) from exc
        try:
            questionnaires[qname] = Questionnaire(q.get("demographics", False), tuple(items))
        except ConfigError as exc:
            raise rewrap(exc, qpath, source) from exc
    try:
        power = power_plan_from_table(data["power"]) if "power" in data else None
    except ConfigError as exc:
        raise rewrap(exc, "", source) from exc
    kw: dict[str, Any] = {
        "name": data["name"], "description": data["description"], "task": data["task"],
        "blocks": tuple(blocks),
        "reach_radius": data.get("reach_radius_m", 0.005),
        "max_trial_time": data.get("max_trial_time_s", 180.0),
        "excessive_force_n": data.get("excessive_force_n", 2.0),
        "repeat_timed_out": data.get("repeat_timed_out", False),
        "path_tolerance_m": data.get("path_tolerance_m", 0.002),
        "poi_spacing": data.get("poi_spacing_m"),
        "block_order": rnd.get("block_order", "fixed"),
        "variant_order": rnd.get("variant_order", "fixed"),
        "probe_condition": probe.get("condition", "none"),
        "probe_variant": probe.get("variant", 0),
        "probe_variants": _tuple(probe["variants"]) if "variants" in probe else None,
        "pre": questionnaires["pre"], "post": questionnaires["post"], "power": power,
        "text": text, "source": source,
    }
    try:
        return Protocol(**kw)
    except ConfigError as exc:
        raise rewrap(exc, "", source) from exc
