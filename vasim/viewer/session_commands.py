"""The experimenter's session commands of the viewer's controller: the input and its
mapping, the subject, the protocol, the reason for a new session, and a protocol's
questionnaire answers (a mixin of :class:`vasim.viewer.controller.TrainingController`, split
from it to keep modules small, as ``condition_commands`` is; it runs on the controller
thread like the rest of the controller)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from vasim.core.config import check_choice, check_type
from vasim.core.errors import ConfigError, FieldError, StoreError
from vasim.haptics.laparoscopic import InputMapping
from vasim.viewer.history import AGAIN_FIELD, check_again_reason
from vasim.viewer.state import PanelState

INPUTS: tuple[str, ...] = ("scripted", "browser", "laparoscopic")
"""Who moves the tool: the scripted operator, the free gizmo on the tip (an experimenter's
option), or the trainee's laparoscopic instrument (mouse, keyboard, gamepad; the trainee
page's default input for a person)."""


class SessionCommands:
    """Input, subject, protocol, again-reason and answers commands (see the controller's
    ``handle``)."""

    panel: PanelState
    input_mapping: InputMapping
    instrument: Any
    _pending: Any

    # Provided by TrainingController (declared here for the type checker only).
    _publish: Callable[..., None]
    _running_stored: Callable[[], bool]
    _select_session: Callable[[], dict[str, Any]]
    _session: Callable[[], Any]
    store: Callable[[], Any]

    def _on_input_mapping(self, value: Any) -> None:
        p = self.panel
        check_type(value, "input_mapping", InputMapping, "an InputMapping")
        if p.mode == "protocol" and self._running_stored():
            raise ConfigError("the running protocol trial keeps its instrument mapping; "
                              "change it between trials", field="input_mapping")
        self.input_mapping = value
        if self.instrument is not None:
            self.instrument.set_mapping(value)

    def _on_input(self, value: Any) -> None:
        p = self.panel
        check_choice(value, "input", INPUTS)
        if value == p.input:
            return
        if self._running_stored() or self._pending is not None:
            raise ConfigError("stop the running trial before changing the input",
                              field="input")
        if p.mode == "protocol" and p.session_id is not None:
            raise ConfigError(f"session {p.session_id} runs with input {p.input!r} "
                              "(stored with the session): every trial of it keeps that "
                              "input", field="input")
        self._publish(input=value)

    def _on_again(self, value: Any) -> None:
        reason = check_again_reason("" if value is None else str(value))
        if self._running_stored():
            raise ConfigError("stop the running trial before giving a reason for a new "
                              "session", field=AGAIN_FIELD)
        self._publish(again=reason, status=(
            f"reason for a new session: {reason}" if reason else "no reason: Start "
            "resumes an open session or starts a first one"))

    def _on_subject(self, value: Any) -> None:
        p = self.panel
        from vasim.records.trial_meta import validate_subject_code

        code = validate_subject_code(str(value).strip())
        if self._running_stored():
            raise ConfigError("stop the running trial before changing the subject",
                              field="subject")
        self._publish(subject=code, label=None, session_id=None, position=None,
                      total=None, completed=None, condition=None, curve=(), again=None)
        if p.mode == "protocol" and p.protocol:
            self._publish(**self._select_session())

    def _on_protocol(self, value: Any) -> None:
        p = self.panel
        from vasim.study.protocol import available_protocols

        check_choice(value, "protocol", available_protocols())
        if self._running_stored():
            raise ConfigError("stop the running trial before changing the protocol",
                              field="protocol")
        self._publish(protocol=value, session_id=None, position=None, total=None,
                      completed=None, condition=None, curve=(), again=None)
        if p.subject:
            self._publish(**self._select_session())

    def _record_answers(self, value: Any) -> None:
        """Stores one questionnaire's answers with the subject's session of the chosen
        protocol (``questionnaire_form``; value: ``(which, TOML text)``), checked as
        ``vasim study answer`` checks them (``record_answers``)."""
        from vasim.study.session import record_answers
        from vasim.viewer.questionnaire_form import (
            QUESTIONNAIRES,
            answers_status,
            parse_answers,
        )

        which, text = value if isinstance(value, tuple) and len(value) == 2 else (None, None)
        if which not in QUESTIONNAIRES or not isinstance(text, str):
            raise ConfigError(f"answers must be (pre|post, TOML text), got {value!r}",
                              field="answers")
        if self.panel.mode != "protocol":
            raise ConfigError("questionnaires belong to a protocol session: switch to "
                              "protocol mode", field="answers")
        try:
            answers = parse_answers(text, which)
        except FieldError as exc:   # a ConfigError or the answers' InputError
            self._publish(status=f"{which} questionnaire not recorded: {exc}")
            raise
        sid = self.panel.session_id
        if sid is None:   # the subject's latest session of the protocol, else a new one
            p = self.panel
            known = self.store().sessions(subject=p.subject, protocol=p.protocol) \
                if p.subject and p.protocol else None
            sid = (int(known["id"].iloc[-1]) if known is not None and len(known)
                   else self._session().id)
        try:
            n = record_answers(self.store(), sid, which, answers,
                               source="the experimenter's questionnaire")
        except (FieldError, StoreError) as exc:
            self._publish(status=f"{which} questionnaire not recorded: {exc}")
            raise
        self._publish(status=answers_status(which, sid, n))


__all__ = ["INPUTS", "SessionCommands"]
