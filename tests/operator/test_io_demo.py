"""nc_programs/io_demo.nc checks clean on the mill with its tools, and is refused without them."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

from daemon_helpers import CNCCTL, REPO

DEMO = REPO / "nc_programs" / "io_demo.nc"
MILL = str(REPO / "config" / "xyz_mill.yaml")


def test_io_demo_checks_with_its_tools_and_names_a_missing_one(tmp_path: Path) -> None:
    tools = tmp_path / "tool.tbl"
    tools.write_text("T1 P1 Z5 D6 ;6 mm end mill\n")
    missing = subprocess.run([*CNCCTL, "check", str(DEMO), "--config", MILL, "--tools",
                              str(tools)], capture_output=True, text=True, timeout=60)
    assert missing.returncode == 2 and ":20:" in missing.stderr
    assert "T2 is not in the tool table" in missing.stderr
    tools.write_text("T1 P1 Z5 D6 ;6 mm end mill\nT2 P2 Z12 D3 ;3 mm drill\n")
    done = subprocess.run([*CNCCTL, "check", str(DEMO), "--config", MILL, "--tools",
                           str(tools), "--json"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert summary["blocks"]["ProbeBlock"] == 1 and summary["blocks"]["StopBlock"] == 3
    # the probe's whole move, with T1's length: down to Z-30 + 5 in machine coordinates
    assert summary["extents_mm"]["z"][0] == -25.0
