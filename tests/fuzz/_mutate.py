"""Hypothesis strategies that break valid inputs in structured ways: byte mutations of a
valid file (truncate, flip, overwrite, insert, duplicate), bad JSON values (wrong types,
NaN/huge/negative numbers, deep nesting) and edits of JSON objects (drop, add, replace
keys), so that generated cases get past the first checks and reach deep code."""

from __future__ import annotations

import copy
import json
import math
from typing import Any

from hypothesis import strategies as st

#: numbers a hostile file states: NaN, infinities, huge, tiny, negative, zero, non-integral
bad_numbers = st.one_of(
    st.sampled_from(
        [0, -1, -(2**31), 2**31, 2**63, 2**64 + 1, 10**30, 1e-300, -0.0, 0.5, 1e308, 3.4e38]
    ),
    st.sampled_from([math.nan, math.inf, -math.inf]),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True, allow_infinity=True),
)
json_scalar = st.one_of(
    st.none(), st.booleans(), bad_numbers, st.text(max_size=8), st.sampled_from(["1", "nan", ""])
)
json_value = st.recursive(
    json_scalar,
    lambda children: (
        st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=4), children, max_size=4)
    ),
    max_leaves=8,
)


def deep_nesting(depth: int) -> Any:
    """A list nested ``depth`` levels deep (deep enough to trouble a recursive reader)."""
    out: Any = 0
    for _ in range(depth):
        out = [out]
    return out


bad_value = st.one_of(
    json_value,
    st.integers(30, 200).map(deep_nesting),
    st.lists(bad_numbers, min_size=1, max_size=5),
    st.lists(st.lists(bad_numbers, min_size=0, max_size=4), max_size=4),
)


@st.composite
def mutated_bytes(draw: st.DrawFn, data: bytes, *, keep: float = 0.1) -> bytes:
    """``data`` with one to four mutations (or, about ``keep`` of the time, intact)."""
    if draw(st.floats(0, 1)) < keep:
        return data
    b = bytearray(data)
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["truncate", "flip", "overwrite", "insert", "zero", "dup"]))
        n = len(b)
        at = draw(st.integers(0, max(n - 1, 0)))
        if op == "truncate":
            del b[at:]
        elif op == "flip" and n:
            b[at] ^= 1 << draw(st.integers(0, 7))
        elif op == "overwrite" and n:
            chunk = draw(st.binary(min_size=1, max_size=8))
            b[at : at + len(chunk)] = chunk
        elif op == "insert":
            b[at:at] = draw(st.binary(min_size=1, max_size=16))
        elif op == "zero" and n:
            width = draw(st.integers(1, 16))
            b[at : at + width] = bytes(len(b[at : at + width]))
        elif op == "dup":
            b[at:at] = b[at : at + draw(st.integers(1, 64))]
    return bytes(b)


@st.composite
def edited_dict(
    draw: st.DrawFn, base: dict[str, Any], values: dict[str, st.SearchStrategy] | None = None
) -> dict[str, Any]:
    """``base`` (deep-copied) with some keys dropped, replaced (by ``values[key]`` when
    given, else a bad JSON value) or added."""
    d = copy.deepcopy(base)
    values = values or {}
    keys = sorted(d)
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(["drop", "replace", "replace", "add"]))
        if op == "drop" and keys:
            d.pop(draw(st.sampled_from(keys)), None)
        elif op == "replace" and keys:
            key = draw(st.sampled_from(keys))
            d[key] = draw(values.get(key, bad_value))
        else:
            d[draw(st.text(min_size=1, max_size=6))] = draw(json_value)
    return d


def json_text(obj: Any) -> str:
    """JSON text of ``obj`` (NaN and infinities as JSON's common extension writes them)."""
    try:
        return json.dumps(obj)
    except (RecursionError, ValueError):
        return "[" * 100000  # deep enough that a recursive reader gives up
