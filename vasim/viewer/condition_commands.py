"""The experimenter's condition commands of the viewer's controller: schema, task, live
f5PL editing and the free-practice label (a mixin of
:class:`vasim.viewer.controller.TrainingController`, split from it to keep modules small;
it runs on the controller thread like the rest of the controller)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

from vasim.core.config import check_choice, check_type, expect
from vasim.core.errors import ConfigError
from vasim.fixtures.logistic import Logistic5
from vasim.fixtures.schema import Schema, load_schema
from vasim.trials.vf import TrialConfig
from vasim.viewer.condition import named_edit
from vasim.viewer.state import (
    PanelState,
    TrialInfo,
    demo_config,
    f5pl_fields,
    schema_choices,
    with_f5pl,
)

DEFAULT_SCHEMA_FOR_TASK: dict[str, str] = {
    "trajectory": "trajectory_following",
    "point": "point_targeting",
}
"""Schema switched to when the chosen task does not fit the current task-specific schema."""


class ConditionCommands:
    """Schema, task, f5PL and label commands (see the controller's ``handle``)."""

    panel: PanelState
    info: TrialInfo
    _base: TrialConfig
    _schema_obj: Schema | None
    _pending: Any

    # Provided by TrainingController (declared here for the type checker only).
    _publish: Callable[..., None]
    _close_trial: Callable[..., None]
    _start_demo: Callable[[TrialConfig], None]
    _running_stored: Callable[[], bool]
    _launch: Callable[..., TrialInfo]
    _free_config: Callable[[], TrialConfig]

    def _set_label(self, value: Any) -> None:
        """The free-practice label of the next free trials without a subject (**decision**:
        a label and a subject exclude each other — setting one clears the other — so a
        trial is a subject's or a labelled practice trial, never both; "" clears it)."""
        from vasim.study.store.vocabulary import validate_label

        if self.panel.mode == "protocol":
            raise ConfigError("protocol trials belong to the subject: labels are for free "
                              "practice", field="label")
        text = str(value).strip() if value is not None else ""
        label = validate_label(text) if text else None
        if self._running_stored() or self._pending is not None:
            raise ConfigError("stop the running trial before changing the label",
                              field="label")
        self._publish(label=label, subject=None if label else self.panel.subject, curve=(),
                      status=f"free practice labelled {label!r}" if label
                      else "free practice without a label")

    def _set_schema(self, name: str) -> None:
        p = self.panel
        if p.mode == "protocol":
            raise ConfigError("the protocol sets the schema; switch to free training to "
                              "choose one", field="schema")
        # viser does not check dropdown values against the options, and
        # load_schema accepts file paths, so any client could make the server read (and
        # broadcast errors about) an arbitrary TOML file; only the offered menu is accepted.
        choices = schema_choices(self._base.schema)
        expect(isinstance(name, str) and name in choices, name,
               "a schema of the Schema menu (an unknown schema is not read)", field="schema")
        if name == p.schema and self._schema_obj is None:
            return
        schema = load_schema(name)
        task = p.task if schema.task in ("any", p.task) else schema.task
        if self._running_stored():
            raise ConfigError("stop the running trial before changing the schema",
                              field="schema")
        self._schema_obj = None
        self._publish(schema=name, task=task, f5pl=f5pl_fields(schema))
        if p.mode == "demo":
            self._close_trial("schema changed")
            cfg = demo_config(self.info)
            variant = cfg.variant if task == cfg.task else 0
            self._start_demo(replace(self._base, schema=name, task=task, variant=variant))  # type: ignore[arg-type]  # strs

    def _set_task(self, task: str) -> None:
        p = self.panel
        if p.mode == "protocol":
            raise ConfigError("the protocol sets the task", field="task")
        check_choice(task, "task", tuple(DEFAULT_SCHEMA_FOR_TASK))
        if task == p.task:
            return
        if self._running_stored():
            raise ConfigError("stop the running trial before changing the task", field="task")
        schema = p.schema
        if load_schema(schema).task not in ("any", task):
            schema = DEFAULT_SCHEMA_FOR_TASK[task]
        if schema != p.schema:
            self._schema_obj = None
        self._publish(task=task, schema=schema, f5pl=f5pl_fields(load_schema(schema)))
        if p.mode == "demo":
            self._close_trial("task changed")
            self._start_demo(replace(self._base, schema=schema, task=task, variant=0))  # type: ignore[arg-type]  # strs

    def _apply_f5pl(self, instance: str, params: Logistic5) -> None:
        """Edits one fixture's f5PL (free training and demo). **decision**: the edit takes
        effect by starting the trial afresh with the edited schema, so every stored trial
        ran with exactly the schema stored with it (a mid-trial change would not be)."""
        p = self.panel
        if p.mode == "protocol":
            raise ConfigError("the protocol's schemas are fixed; edit f5PL parameters in "
                              "free training", field="f5pl")
        check_type(params, "f5pl", Logistic5, "f5PL parameters (a Logistic5)")
        shipped = load_schema(p.schema)
        base = self._schema_obj if self._schema_obj is not None else shipped
        edited = named_edit(with_f5pl(base, instance, params), shipped)
        self._schema_obj = edited
        self._publish(f5pl=f5pl_fields(edited),
                      status=f"{instance}: f5PL a={params.a:g} b={params.b:g} c={params.c:g} "
                             f"d={params.d:g} g={params.g:g}; trials are stored as schema "
                             f"{edited.name}")
        if p.mode == "demo":
            self._close_trial("f5PL edited")
            self._start_demo(demo_config(self.info))
        elif self._running_stored():
            self._close_trial("f5PL edited")
            self._launch(self._free_config(), mode="free", schema=edited, input_kind=p.input)
            self._publish(running=True, summary=None)


__all__ = ["DEFAULT_SCHEMA_FOR_TASK", "ConditionCommands"]
