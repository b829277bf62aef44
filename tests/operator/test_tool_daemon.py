"""The tool table through a real cncd: `cncctl tool` edits it, it survives a restart, a job
checks T words against it, and an M6 waits at the change position for `cncctl resume`."""

from __future__ import annotations

import json
import time
from pathlib import Path

from daemon_helpers import REPO, raw, running_cncd, start_run


def mill_config(tmp_path: Path) -> Path:
    config = tmp_path / "mill.yaml"
    config.write_text((REPO / "config" / "xyz_mill.yaml").read_text()
                      + "tools:\n  change_position_mm: [5.0, 5.0, 40.0]\n")
    return config


def test_cncctl_tool_edits_the_daemons_table_and_it_is_kept(tmp_path: Path) -> None:
    table = str(REPO / "config" / "xy_table.yaml")
    with running_cncd(tmp_path, "--config", table) as d:
        assert "no tools" in d.cncctl("tool", "list").stdout
        done = d.cncctl("tool", "set", "T3", "Z12.5", "D6", "--comment", "6 mm end mill")
        assert done.returncode == 0, done.stderr
        assert "T3" in done.stdout and "12.5000" in done.stdout
        assert d.cncctl("tool", "set", "T4", "Z-2").returncode == 0
        assert d.cncctl("tool", "delete", "T4").returncode == 0
        refused = d.cncctl("tool", "delete", "T4")
        assert refused.returncode == 2 and "T4 is not in the tool table" in refused.stderr
        assert d.cncctl("tool", "set", "T5", "Z5000").returncode == 2  # out of range
        bad = raw(d.socket_path, b'{"cmd": "tool", "action": "set", "tool": true}\n')
        assert bad[0]["error"] == "bad-field"
        assert (d.state_dir / "tool.tbl").read_text() == "T3 P3 Z12.5 D6 ;6 mm end mill\n"
    # the same state directory: the table is kept
    with running_cncd(tmp_path, "--config", table) as d:
        tools = json.loads(d.cncctl("tool", "list", "--json").stdout)
        assert tools == [{"tool": 3, "pocket": 3, "length_mm": 12.5, "diameter_mm": 6.0,
                          "comment": "6 mm end mill"}]


def test_a_job_is_checked_against_the_table_and_m6_waits_for_resume(tmp_path: Path) -> None:
    program = tmp_path / "tc.nc"
    program.write_text("G21 G90 G0 X10 Y10 Z5\nM3 S1000\nT3 M6\nG43\nG0 Z0\nG1 X20 F600\n"
                       "M5\nM2\n")
    unknown = tmp_path / "unknown.nc"
    unknown.write_text("G0 X1\nT9 M6\nM2\n")
    with running_cncd(tmp_path, "--config", str(mill_config(tmp_path))) as d:
        d.cncctl("reset")
        assert d.cncctl("tool", "set", "T3", "Z12.5").returncode == 0
        rejected = start_run(d, unknown)
        out, err = rejected.communicate(timeout=60)
        assert rejected.returncode == 2 and "unknown.nc:2:1: error: T9 is not in the tool" in err
        run = start_run(d, program)
        try:
            deadline = time.monotonic() + 30
            while d.status()["state"] != "PAUSED":
                assert time.monotonic() < deadline and run.poll() is None
                time.sleep(0.05)
            status = d.status()
            assert status["line"] == 3 and status["position_mm"] == {"x": 5.0, "y": 5.0,
                                                                     "z": 40.0}
            assert status["tool_change"].startswith("tool change at line 3 (M6): put in T3")
            time.sleep(0.3)
            assert d.status()["state"] == "PAUSED"  # waits for the operator
            assert d.cncctl("tool", "set", "T3", "Z1").returncode == 2  # not during a job
            assert d.cncctl("resume").returncode == 0
            out, _ = run.communicate(timeout=60)
        finally:
            run.kill()
            run.wait()
        events = [json.loads(line) for line in out.splitlines()]
        tool = [e for e in events if e["event"] == "tool"]
        assert len(tool) == 1 and tool[0]["line"] == 3 and tool[0]["tool"] == 3
        assert tool[0]["table_length_mm"] == 12.5 and tool[0]["length_mm"] == 0.0  # G43 later
        assert tool[0]["t_s"] > 0
        final = events[-1]
        assert run.returncode == 0 and final["event"] == "done"
        assert final["final_position_mm"] == {"x": 20.0, "y": 5.0, "z": 12.5}
