"""Outside text quoted in an error message stays a short line whatever it holds."""

from __future__ import annotations

import ast

from hypothesis import given
from hypothesis import strategies as st

from fabwire.errors import excerpt


@given(st.text() | st.binary(), st.integers(1, 100))
def test_an_excerpt_is_bounded_and_a_prefix_of_what_it_quotes(value: str | bytes, limit: int) -> None:
    shown = excerpt(value, limit)
    assert len(shown) <= limit + 4
    if shown == repr(value):
        return
    assert shown.endswith("…" + shown[-1])
    kept = ast.literal_eval(shown[:-2] + shown[-1])
    assert value.startswith(kept)


def test_short_text_is_quoted_whole_and_long_text_is_marked_cut() -> None:
    assert excerpt("office") == "'office'"
    assert excerpt("9" * 5000, 12) == "'999999999999…'"
    assert excerpt("\x1f" * 30, 20) == "'\\x1f\\x1f\\x1f\\x1f\\x1f…'"
