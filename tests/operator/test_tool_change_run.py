"""M6 in an embedded `cncctl run` (a real process): to the change position, spindle off, the
operator's prompt, a wait until Enter, the new tool's length; the tool event in --json."""

from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path

from daemon_helpers import CNCCTL, REPO


def mill_with_tools(tmp_path: Path) -> Path:
    (tmp_path / "tool.tbl").write_text("T1 P1 Z10.5 D6 ;end mill\nT2 P2 Z-3 D3\n")
    config = tmp_path / "mill.yaml"
    config.write_text((REPO / "config" / "xyz_mill.yaml").read_text()
                      + "tools:\n  change_position_mm: [0.0, 0.0, 50.0]\n"
                        "  table_file: tool.tbl\n")
    return config


def test_m6_waits_at_the_change_position_until_enter(tmp_path: Path) -> None:
    program = tmp_path / "tc.nc"
    program.write_text("G21 G90 G0 X10 Y10 Z5\nM3 S1000\nT1 M6\nG43\nG0 Z0\nG1 X20 F600\nM2\n")
    proc = subprocess.Popen([*CNCCTL, "run", str(program), "--json", "--virtual-time",
                             "--config", str(mill_with_tools(tmp_path))],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stdin is not None
        while True:
            event = json.loads(proc.stdout.readline())
            if event["event"] == "tool":
                break
            assert event["event"] in ("start", "progress", "output"), event
        assert event["line"] == 3 and event["tool"] == 1 and event["table_length_mm"] == 10.5
        assert event["position_mm"] == [0.0, 0.0, 50.0] and event["t_s"] > 0
        time.sleep(0.5)
        assert proc.poll() is None  # waits for the operator
        proc.stdin.write("\n")
        proc.stdin.flush()
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    final = json.loads(out.splitlines()[-1])
    assert proc.returncode == 0 and final["event"] == "done", err
    assert "tool change at line 3 (M6): put in T1 (length 10.5 mm in the table)" in err
    # G43 after the change: Z0 in the program is the tool's length above machine zero
    assert final["final_position_mm"] == {"x": 20.0, "y": 0.0, "z": 10.5}


def test_an_unknown_tool_is_refused_before_any_motion(tmp_path: Path) -> None:
    program = tmp_path / "bad.nc"
    program.write_text("G0 X5\nT9 M6\nM2\n")
    done = subprocess.run([*CNCCTL, "run", str(program), "--virtual-time", "--config",
                           str(mill_with_tools(tmp_path))], capture_output=True, text=True,
                          timeout=60, stdin=subprocess.DEVNULL)
    assert done.returncode == 2
    assert f"{program}:2:" in done.stderr and "T9 is not in the tool table" in done.stderr
