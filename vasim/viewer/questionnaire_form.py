"""A protocol's questionnaires on the experimenter's page (issue #28: a session run in the
viewer records its questionnaires as ``vasim study answer`` does).

**Decision** (the form): one text area holding the answers in the answers file's TOML
(``vasim.study.session.load_answers_file``, one questionnaire's table without its
``[pre]`` / ``[post]`` header), pre-filled by :func:`answers_template` with every item of
the chosen protocol's questionnaire, its prompt and allowed values as comments. The
experimenter fills in the values with the subject and presses "Record answers"; the
controller checks them with the protocol (``validate_answers`` through
``record_answers``: the same rules and error messages as the command line) and stores them
with the session. A form of typed widgets per item type (ratings per condition, sets of
conditions) would duplicate those rules in the page; the TOML text carries every type.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import viser

from vasim.viewer.state import Command, PanelState
from vasim.viewer.views import set_gui_value

QUESTIONNAIRES: tuple[str, ...] = ("pre", "post")

_EXAMPLES = {"choice": '""', "text": '""', "integer": "0", "likert": "3",
             "condition_choice": '""', "condition_rating": "{}", "condition_sets": "[]"}


def _allowed(item: Any) -> str:
    t = item.type
    if t == "choice":
        return "one of: " + ", ".join(item.options)
    if t == "condition_choice":
        return "one of: " + ", ".join(item.conditions)
    if t == "integer":
        return f"an integer {item.min}..{item.max}"
    if t == "likert":
        anchors = f" ({'; '.join(item.anchors)})" if item.anchors else ""
        return f"1..5{anchors}"
    if t == "condition_rating":
        return (f"{{ condition = {item.min}..{item.max} }} for each of: "
                + ", ".join(item.conditions))
    if t == "condition_sets":
        return (f"up to {item.max_entries} lists of >= {item.min_size} of: "
                + ", ".join(item.conditions))
    return f"text, at most {item.max_length} characters"


def answers_template(protocol: Any, which: str) -> str:
    """The TOML the experimenter fills in for one questionnaire of ``protocol`` (module
    docstring); an optional item is commented out.

    Example:
        >>> from vasim.study.protocol import load_protocol
        >>> print(answers_template(load_protocol("mrcp_suture_dynamic"), "post"))
        ... # doctest: +NORMALIZE_WHITESPACE
        # post questionnaire of mrcp_suture_dynamic
        # Which mode did you prefer? (one of: stdt, mrcp)
        best_mode = ""
        # Free comments (text, at most 2000 characters; optional)
        # comments = ""
    """
    from vasim.study.store import DEMOGRAPHIC_FIELDS

    q = getattr(protocol, which)
    lines = [f"# {which} questionnaire of {protocol.name}"]
    if q.demographics:
        for name, allowed in DEMOGRAPHIC_FIELDS.items():
            lines += [f"# {name} (one of: {', '.join(allowed)})", f'{name} = ""']
    for item in q.items:
        opt = "" if item.required else "; optional"
        lines.append(f"# {item.prompt} ({_allowed(item)}{opt})")
        lines.append(f"{'' if item.required else '# '}{item.id} = {_EXAMPLES[item.type]}")
    if len(lines) == 1:
        lines.append("# (this protocol has no such questionnaire)")
    return "\n".join(lines)


def parse_answers(text: str, which: str) -> dict[str, Any]:
    """The answers table of the form's text (item -> answer).

    Raises:
        ConfigError: invalid TOML (line and column), or a nested table.
    """
    from vasim.core.config import expect, parse_toml

    data = parse_toml(text, kind=f"{which} answers")
    for key, value in data.items():
        expect(not isinstance(value, dict) or all(isinstance(v, int) for v in value.values()),
               value, f"an answer, not a table: write the {which} answers as item = value "
               "lines (no [pre]/[post] header)", field=f"{which}.{key}")
    return data


class QuestionnaireForm:
    """The "Questionnaire" folder of the experimenter's page (module docstring).

    Args:
        server: the experimenter's page. submit: queues a controller ``Command``.
        guard: wraps a callback (errors logged and notified, never raised into viser).
    """

    def __init__(self, server: viser.ViserServer, submit: Callable[[Command], None],
                 guard: Callable[[Callable[..., Any]], Callable[..., Any]]) -> None:
        self._submit = submit
        self._key: tuple[str | None, str] | None = None
        with server.gui.add_folder("Questionnaire", expand_by_default=False):
            self.which = server.gui.add_dropdown("Questionnaire", QUESTIONNAIRES,
                                                 initial_value="post")
            self.text = server.gui.add_text("Answers (TOML)", initial_value="",
                                            multiline=True)
            self.record = server.gui.add_button(
                "Record answers", hint="checks the answers with the protocol and stores "
                "them with the subject's session (as vasim study answer does)")
        self.record.on_click(guard(lambda _: self.submit()))
        self.which.on_update(guard(lambda _: self._fill(self._protocol, force=True)))
        self._protocol: str | None = None

    def submit(self) -> None:
        """Queues the answers as written (what the button does)."""
        self._submit(Command("answers", (str(self.which.value), str(self.text.value))))

    def show(self, state: PanelState) -> None:
        """Pre-fills the template when the protocol or the questionnaire changed."""
        self._protocol = state.protocol
        self._fill(state.protocol)

    def _fill(self, protocol: str | None, *, force: bool = False) -> None:
        key = (protocol, str(self.which.value))
        if key == self._key and not force:
            return
        self._key = key
        if protocol is None:
            set_gui_value(self.text, "# pick a protocol first")
            return
        from vasim.study.protocol import load_protocol

        set_gui_value(self.text, answers_template(load_protocol(protocol), key[1]))


def answers_status(which: str, session_id: int, n: int) -> str:
    """The status line after answers were stored."""
    return f"{which} questionnaire of session {session_id} recorded ({n} answer rows)"


__all__ = ["QUESTIONNAIRES", "QuestionnaireForm", "answers_status", "answers_template",
           "parse_answers"]
