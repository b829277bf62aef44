"""The control socket's request parser: any line gives a Request or a ProtocolError, nothing
else (an exception of another kind once took the daemon down mid-job)."""

from __future__ import annotations

import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.operator.daemon.protocol import COMMANDS, ProtocolError, Request, parse_request

JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.floats(allow_nan=True) | st.text(max_size=80)
    | st.integers() | st.integers(min_value=10**60, max_value=10**80),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=10), inner,
                                                                max_size=4),
    max_leaves=12)
REQUESTS = st.fixed_dictionaries(
    {"cmd": st.sampled_from(sorted(COMMANDS)) | st.text(max_size=8)},
    optional={"id": JSON_VALUES, "percent": JSON_VALUES, "lines": JSON_VALUES,
              "axes": JSON_VALUES, "topics": JSON_VALUES, "program_bytes": JSON_VALUES,
              "action": JSON_VALUES, "values": JSON_VALUES, "axis": JSON_VALUES,
              "extra": JSON_VALUES})


def _parse(line: bytes) -> Request | None:
    try:
        return parse_request(line)
    except ProtocolError:
        return None


@settings(max_examples=400, deadline=None)
@given(REQUESTS)
def test_any_json_request_is_parsed_or_refused(obj: dict) -> None:
    _parse(json.dumps(obj).encode())


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=200))
def test_any_bytes_are_parsed_or_refused(line: bytes) -> None:
    _parse(line)


@pytest.mark.parametrize("line", [
    b'{"cmd":"feed","percent":' + b"9" * 5000 + b"}",  # over Python's 4300-digit int limit
    b'{"cmd":"status","id":' + b"9" * 5000 + b"}",
    b'{"cmd":"status","id":[1]}',
    b'{"cmd":"status","id":"' + b"x" * 100 + b'"}',
    b'{"cmd":"status","id":' + b"9" * 30 + b"}",
    b"[" * 100_000,
])
def test_requests_the_daemon_once_choked_on_are_refused(line: bytes) -> None:
    with pytest.raises(ProtocolError):
        parse_request(line)


def test_a_good_id_is_kept() -> None:
    assert parse_request(b'{"cmd":"status","id":7}').id == 7
    assert parse_request(b'{"cmd":"status","id":"' + b"x" * 64 + b'"}').id == "x" * 64
    assert parse_request(b'{"cmd":"status"}').id is None
