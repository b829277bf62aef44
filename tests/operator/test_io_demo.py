"""nc_programs/io_demo.nc checks clean on the mill with its tools, and is refused without them."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

from daemon_helpers import CNCCTL, REPO, run_confirming_tools

DEMO = REPO / "nc_programs" / "io_demo.nc"
MILL = str(REPO / "config" / "xyz_mill.yaml")


def test_io_demo_checks_with_its_tools_and_names_a_missing_one(tmp_path: Path) -> None:
    tools = tmp_path / "tool.tbl"
    tools.write_text("T1 P1 Z5 D6 ;6 mm end mill\n")
    missing = subprocess.run([*CNCCTL, "check", str(DEMO), "--config", MILL, "--tools",
                              str(tools)], capture_output=True, text=True, timeout=60)
    assert missing.returncode == 2 and ":24:" in missing.stderr
    assert "T2 is not in the tool table" in missing.stderr
    tools.write_text("T1 P1 Z5 D6 ;6 mm end mill\nT2 P2 Z12 D3 ;3 mm drill\n")
    done = subprocess.run([*CNCCTL, "check", str(DEMO), "--config", MILL, "--tools",
                           str(tools), "--json"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert summary["blocks"]["ProbeBlock"] == 1 and summary["blocks"]["StopBlock"] == 3
    # the probe's whole move, with T1's length: down to Z-30 + 5 in machine coordinates
    assert summary["extents_mm"]["z"][0] == -25.0


def test_io_demo_runs_on_the_sim_card_with_its_tool_changes_and_probe(tmp_path: Path) -> None:
    tools = tmp_path / "tool.tbl"
    tools.write_text("T1 P1 Z5 D6\nT2 P2 Z12 D3\n")
    events = run_confirming_tools([*CNCCTL, "run", str(DEMO), "--config", MILL, "--tools",
                                   str(tools), "--drive-option",
                                   "probe_workpiece_mm=-50,-50,-50,50,50,0",
                                   "--virtual-time", "--json"])
    outputs = [(e["line"], e["name"], e["value"]) for e in events if e["event"] == "output"]
    output_t_s = [e["t_s"] for e in events if e["event"] == "output"]
    events = [e for e in events if e["event"] != "output"]
    kinds = [(e["event"], e.get("line")) for e in events]
    assert kinds == [("start", None), ("tool", 8), ("probe", 16), ("tool", 24), ("done", 30)]
    names = {name for _, name, _ in outputs}
    assert {"spindle", "coolant_flood", "digital_0", "analog_0"} <= names, outputs
    # the probe's trip ends a stretch, not the job: nothing goes safe there, and the outputs
    # of the stretches after it are timed on the run's one time line
    assert [(line, v) for line, n, v in outputs if n == "digital_0"] == [(12, True), (30, False)]
    assert output_t_s == sorted(output_t_s)
    assert [v for _, n, v in outputs if n == "spindle"][-1] == "off"  # stopped by the end
    tool1, probe, tool2 = events[1], events[2], events[3]
    assert (tool1["tool"], tool1["length_mm"], tool2["tool"], tool2["length_mm"]) == (1, 0, 2, 12)
    assert tool1["t_s"] < probe["t_s"] < tool2["t_s"]  # one time line over the stretches
    assert probe["tripped"] and -0.05 < probe["trip_mm"][2] <= 0.0  # the face at machine Z0
    # the program's last Z: G0 Z20 with T2's length 12 in force
    assert events[-1]["final_position_mm"] == {"x": 25.0, "y": 25.0, "z": 32.0}
