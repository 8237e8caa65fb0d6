"""`fabwire.jsontext.parse_json`, the one reader of JSON from outside: what it refuses, each row with its source."""

from __future__ import annotations

import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fabwire.errors import InputError
from fabwire.jsontext import MAX_DEPTH, parse_json

REFUSED = [
    ("NaN", "RFC 8259 §6: no NaN (Python's parser takes it)"),
    ('{"id": NaN}', "RFC 8259 §6: NaN inside an object"),
    ("[Infinity]", "RFC 8259 §6: no Infinity"),
    ("-Infinity", "RFC 8259 §6: no -Infinity"),
    ("1e999", "RFC 8259 §6: a number beyond a double (IEEE 754 binary64, RFC 8259 §6 interoperability)"),
    ("[-1e400]", "the same, negative"),
    ("[" * (MAX_DEPTH + 1) + "]" * (MAX_DEPTH + 1), "fabwire's nesting bound (MAX_DEPTH)"),
    ("[" * 100_000, "a recursion bomb"),
    ("1" * 5000, "an integer past Python's 4300-digit conversion limit"),
    (b"\xff\xfe", "RFC 8259 §8.1: UTF-8 only"),
    ("{'a': 1}", "RFC 8259 §7: strings are in double quotes"),
]


@pytest.mark.parametrize(("text", "source"), REFUSED, ids=[source for _, source in REFUSED])
def test_refused_with_one_input_error(text: str | bytes, source: str) -> None:
    with pytest.raises(InputError):
        parse_json(text)


@given(st.recursive(st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False, allow_infinity=False)
                    | st.text(), lambda inner: st.lists(inner, max_size=4)
                    | st.dictionaries(st.text(), inner, max_size=4), max_leaves=20))
def test_every_json_document_reads_back(value: object) -> None:
    assert parse_json(json.dumps(value)) == value
