"""Operators read words and numbers, not Python reprs: positions, pulses, offset tables."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

from daemon_helpers import CNCCTL, REPO, running_cncd

from controller.offsets import OffsetTable, describe, describe_text, select, with_g92, with_system
from controller.operator.words import axes_text, offsets_table, pulses_text


def test_axes_and_pulses_text() -> None:
    assert axes_text({"x": 9.9994, "y": 0.0}) == "X 9.999 Y 0.000 mm"
    assert axes_text({}) == "unknown"
    same = {"x": {"commanded": 12, "executed": 12}, "y": {"commanded": -3, "executed": -3}}
    assert pulses_text(same) == "X 12 Y -3 (all executed)"
    short = same | {"y": {"commanded": -3, "executed": -2}}
    assert pulses_text(short) == "X 12 executed of 12 commanded, Y -2 executed of -3 commanded"


def test_offsets_table_has_only_the_machines_axes() -> None:
    table = with_g92(select(with_system(OffsetTable(), 2, (10.0, 5.0, 7.0)), 2), (1, 0, 0))
    text = offsets_table(describe(table), ["x", "y"])
    lines = text.splitlines()
    assert len(lines) == 9 and "Z" not in text and "{" not in text
    assert lines[0].split() == ["work", "offsets", "(mm)", "X", "Y"]
    assert lines[2].split() == ["G55", "active", "10.000", "5.000"]
    assert lines[-1].split() == ["work", "origin", "11.000", "5.000"]
    log = describe_text(table, ["x", "y"])
    assert log == "G55 active, work origin X11.000 Y5.000; G55 X10.000 Y5.000; G92 X1.000 Y0.000"


def test_a_local_run_ends_with_a_readable_position() -> None:
    proc = subprocess.run([*CNCCTL, "run", "--virtual-time", str(REPO / "nc_programs/arcs.nc")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "final position X 0.000 Y 0.000 mm, pulses X 0 Y 0 (all executed)" in proc.stdout
    assert "{" not in proc.stdout


def test_offset_set_prints_a_table_and_json_on_request(tmp_path: Path) -> None:
    with running_cncd(tmp_path) as d:
        d.cncctl("reset")
        done = d.cncctl("offset", "set", "G55", "X10", "Y5")
        assert done.returncode == 0, done.stderr
        lines = done.stdout.splitlines()
        assert len(lines) == 9 and "Z" not in done.stdout and "{" not in done.stdout
        assert lines[2].split() == ["G55", "10.000", "5.000"]  # G54 stays the active one
        shown = d.cncctl("offset", "show", "--json")
        assert json.loads(shown.stdout)["systems_mm"]["G55"] == {"x": 10.0, "y": 5.0, "z": 0.0}
        log = d.cncctl("log").stdout
        assert "work offsets (set G55): G54 active, work origin X0.000 Y0.000; " \
               "G55 X10.000 Y5.000" in log
