"""The work-offset table (controller/offsets.py): helpers, describe, and its JSON file."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.errors import CncError, OffsetsError
from controller.offsets import (
    SYSTEM_NAMES,
    OffsetTable,
    describe,
    load_offsets,
    save_offsets,
    select,
    to_machine_mm,
    to_program_mm,
    with_g92,
    with_system,
    work_origin_mm,
)

FINITE = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False)
POINT = st.tuples(FINITE, FINITE, FINITE)
TABLES = st.builds(OffsetTable, st.tuples(*[POINT] * 6), POINT, st.integers(1, 6))


def test_default_table_is_zero_and_g54() -> None:
    t = OffsetTable()
    assert t.active == 1 and t.active_name == "G54"
    assert t.systems_mm == ((0.0, 0.0, 0.0),) * 6 and t.g92_mm == (0.0, 0.0, 0.0)
    assert np.array_equal(work_origin_mm(t), np.zeros(3))


def test_helpers_make_new_tables_and_sum_the_active_origin_with_g92() -> None:
    t = with_system(OffsetTable(), 2, (100, 50, -5))
    t = with_g92(select(t, 2), (1.5, 0, 0))
    assert t.active_name == "G55" and t.origin_mm(2) == (100.0, 50.0, -5.0)
    assert np.array_equal(work_origin_mm(t), [101.5, 50.0, -5.0])
    assert np.array_equal(work_origin_mm(select(t, 1)), [1.5, 0.0, 0.0])  # G92: every system
    assert np.allclose(to_program_mm(t, to_machine_mm(t, [1, 2, 3])), [1, 2, 3])
    assert OffsetTable().origin_mm(2) == (0.0, 0.0, 0.0)  # the original is unchanged


@pytest.mark.parametrize("build", [
    lambda: OffsetTable(active=0), lambda: OffsetTable(active=7),
    lambda: OffsetTable(active=True),
    lambda: OffsetTable(systems_mm=((0.0, 0.0, 0.0),) * 5),
    lambda: OffsetTable(g92_mm=(0.0, float("nan"), 0.0)),
    lambda: OffsetTable(g92_mm=(0.0, 0.0)),  # type: ignore[arg-type]
    lambda: with_system(OffsetTable(), 9, (0, 0, 0)),
    lambda: with_system(OffsetTable(), 1, (0, "1", 0)),
    lambda: select(OffsetTable(), 0),
])
def test_invalid_tables_are_refused(build) -> None:  # noqa: ANN001
    with pytest.raises(ValueError):
        build()


def test_describe_is_json_for_status() -> None:
    t = with_g92(select(with_system(OffsetTable(), 3, (1, 2, 3)), 3), (0, 0, 1))
    d = json.loads(json.dumps(describe(t)))
    assert d["active"] == "G56"
    assert list(d["systems_mm"]) == list(SYSTEM_NAMES)
    assert d["systems_mm"]["G56"] == {"x": 1.0, "y": 2.0, "z": 3.0}
    assert d["g92_mm"] == {"x": 0.0, "y": 0.0, "z": 1.0}
    assert d["work_origin_mm"] == {"x": 1.0, "y": 2.0, "z": 4.0}


@settings(max_examples=40, deadline=None)
@given(TABLES)
def test_save_and_load_round_trip(table: OffsetTable) -> None:
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "offsets.json"
        save_offsets(path, table)
        assert load_offsets(path) == table
        assert os.listdir(tmp) == ["offsets.json"]  # no temporary file left behind


def test_a_missing_file_is_the_default_table(tmp_path: Path) -> None:
    assert load_offsets(tmp_path / "none.json") == OffsetTable()


def test_save_replaces_the_file_and_keeps_its_mode(tmp_path: Path) -> None:
    path = tmp_path / "offsets.json"
    save_offsets(path, OffsetTable())
    os.chmod(path, 0o600)
    save_offsets(str(path), select(OffsetTable(), 4))
    assert load_offsets(path).active_name == "G57"
    assert os.stat(path).st_mode & 0o777 == 0o600
    assert json.loads(path.read_text())["format"] == "phcnc-offsets"


def test_a_failed_write_leaves_the_old_table(tmp_path: Path, monkeypatch) -> None:  # noqa: ANN001
    path = tmp_path / "offsets.json"
    save_offsets(path, select(OffsetTable(), 2))

    def fail(*_args: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", fail)
    with pytest.raises(OffsetsError, match="No space left on device") as info:
        save_offsets(path, select(OffsetTable(), 3))
    assert info.value.path == str(path)
    assert load_offsets(path).active_name == "G55"
    assert sorted(os.listdir(tmp_path)) == ["offsets.json"]


def test_a_folder_that_does_not_exist_is_an_offsets_error(tmp_path: Path) -> None:
    with pytest.raises(OffsetsError, match="cannot write"):
        save_offsets(tmp_path / "no" / "offsets.json", OffsetTable())


def _valid() -> dict:
    from controller.offsets import to_json

    return to_json(OffsetTable())


@pytest.mark.parametrize(("text", "message"), [
    ("{not json", "corrupt offset table"),
    ('{"format": "phcnc-offsets", "version": 1, "act', "corrupt offset table"),
    ("\xff\xfe", "corrupt offset table"),
    ("[]", "one JSON object"),
    (json.dumps({**_valid(), "extra": 1}), "unknown key 'extra'"),
    (json.dumps({k: v for k, v in _valid().items() if k != "g92_mm"}), "missing key 'g92_mm'"),
    (json.dumps({**_valid(), "version": 2}), "version must be 1"),
    (json.dumps({**_valid(), "format": "other"}), "format must be"),
    (json.dumps({**_valid(), "active": "G59.1"}), "active must be one of"),
    (json.dumps({**_valid(), "g92_mm": [0, 0]}), "three numbers"),
    (json.dumps({**_valid(), "g92_mm": [0, True, 0]}), "three numbers"),
    (json.dumps({**_valid(), "g92_mm": "0 0 0"}), "g92_mm must be"),
    (json.dumps({**_valid(), "systems_mm": {"G54": [0, 0, 0]}}), "systems_mm must map"),
    (json.dumps({**_valid(), "g92_mm": [0, "NaN", 0]}), "three numbers"),
    (json.dumps(_valid()).replace('"g92_mm": [0.0', '"g92_mm": [NaN'), "must be finite"),
    ("x" * 70_000, "larger than"),
])
def test_a_corrupt_or_invalid_file_names_itself(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "offsets.json"
    path.write_bytes(b"\xff\xfe" if text == "\xff\xfe" else text.encode())
    with pytest.raises(OffsetsError, match=message) as info:
        load_offsets(path)
    assert isinstance(info.value, CncError)
    assert str(info.value).startswith(f"{path}: ")


def test_an_unreadable_file_is_an_offsets_error(tmp_path: Path) -> None:
    with pytest.raises(OffsetsError, match="cannot read"):
        load_offsets(tmp_path)  # a folder
