"""A trial's identity: subject codes are pseudonyms, and a bad one is named, not echoed."""

from __future__ import annotations

import pytest

from vasim.core.errors import ConfigError
from vasim.records.trial_meta import TrialMeta, validate_subject_code


@pytest.mark.parametrize("code", ["S01", "sub_7", "A-1", "x" * 32])
def test_valid_codes_pass_unchanged(code: str) -> None:
    assert validate_subject_code(code) == code


@pytest.mark.parametrize("code", ["", "x" * 33, "Jane Doe", "S01\n", "é1", 7, None])
def test_invalid_codes_are_refused_with_the_field(code: object) -> None:
    with pytest.raises(ConfigError) as err:
        validate_subject_code(code)
    assert err.value.field == "subject"


def test_a_huge_code_is_named_in_a_short_message() -> None:
    """Issue #16: a 100,000-character subject code was echoed whole."""
    with pytest.raises(ConfigError) as err:
        validate_subject_code("x" * 100_000)
    msg = str(err.value)
    assert len(msg) < 400 and "100,000 characters" in msg


def test_a_trial_may_have_no_subject() -> None:
    meta = TrialMeta(subject=None, task="trajectory")
    assert meta.subject is None
