"""G38 on the backends with a simulated peer in its own process: the serial card's probe
input (an io bit of its status frame, docs/serial-protocol.md) and the CANopen drives' touch
probe (docs/canopen.md)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest
import yaml
from daemon_helpers import LOADED_CANOPEN, LOADED_LINK, run_confirming_tools
from test_canopen_process import peer as canopen_peer
from test_io_peers import peer as io_peer
from test_serial_card import CLI, REPO
from test_serial_card import peer as serial_peer

from drivers.io_peer import read_outputs


def test_a_probe_on_the_serial_card_through_its_peer_process(tmp_path: Path) -> None:
    program = tmp_path / "probe.nc"
    program.write_text("G21 G90 F300\nG38.2 X20\nG91 G0 X-2\nG90 G0 X#5061\nM2\n")
    with serial_peer("probe_workpiece_mm=10,-50,-50,50,50,50") as (port, _):
        done = subprocess.run([*CLI, "run", str(program), "--config", "serial", "--json",
                               "--drive-option", f"port={port}", *LOADED_LINK["serial"]],
                              capture_output=True, text=True,
                              timeout=120, stdin=subprocess.DEVNULL, cwd=REPO)
    events = [json.loads(line) for line in done.stdout.splitlines()]
    assert done.returncode == 0, (done.stderr, events[-1].get("message"))
    (probe,) = [e for e in events if e["event"] == "probe"]
    trip_x, stop_x = probe["trip_mm"][0], probe["stop_mm"][0]
    # the face at X10, seen within a few status periods of the link and the servo's lag
    assert probe["tripped"] and 9.95 < trip_x <= 10.05
    # The card cannot give back the frames it has queued (up to the high-water mark, 100 ms):
    # the stop at Amax starts behind them, so the overtravel is at most those at F300 (5 mm/s),
    # a couple of cycles and the stop distance.
    assert 0.0 <= stop_x - trip_x < 5.0 * (0.100 + 0.020) + 2 * 5.0**2 / (2 * 2450.0)
    # G91 X-2 from the stop point, then G0 X#5061: the trip point, as the program reads it
    assert events[-1]["final_position_mm"]["x"] == pytest.approx(trip_x, abs=0.0011)


def test_a_serial_card_without_contact_ends_a_g38_2_as_an_error(tmp_path: Path) -> None:
    program = tmp_path / "probe.nc"
    program.write_text("G21 G90 F600\nG38.2 X5\nM2\n")
    with serial_peer() as (port, _):
        done = subprocess.run([*CLI, "run", str(program), "--config", "serial",
                               "--drive-option", f"port={port}", *LOADED_LINK["serial"]],
                              capture_output=True, text=True,
                              timeout=120, stdin=subprocess.DEVNULL, cwd=REPO)
    assert done.returncode == 4
    assert "line 2: G38.2: the probe move ended without making contact" in done.stderr \
        + done.stdout


# Both ways (0x1016 on the drives, the host's check of theirs): a machine whose two cores are
# shared with other work starves the host's SYNC thread of more than the default 300 ms at
# times, and the drives then fault on the master's heartbeat, whatever the probe does.
LOADED = LOADED_LINK["canopen"]


def canopen_run(path: str, program: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, "run", str(program), "--config", "canopen", "--json",
                           "--drive-option", f"channel={path}", "--drive-option",
                           "touch_probe=true", *LOADED], capture_output=True, text=True,
                          timeout=120,
                          stdin=subprocess.DEVNULL, cwd=REPO)


def test_a_probe_on_canopen_latches_the_trip_in_the_drives_touch_probe(tmp_path: Path) -> None:
    program = tmp_path / "probe.nc"
    # in at F1200 (20 um per 1 ms cycle) to the face, then out of the work through it
    program.write_text("G21 G90 F1200\nG38.2 X20\nG0 X12\nG38.4 X0\nG0 X#5061\nM2\n")
    face_x = 10.0004  # between two of the drives' counts (1 um), crossed mid-cycle
    with canopen_peer(f"probe_workpiece_mm={face_x},-50,-50,50,50,50") as (_, path):
        done = canopen_run(path, program)
    events = [json.loads(line) for line in done.stdout.splitlines()]
    assert done.returncode == 0, (done.stderr, events[-1].get("message"))
    made, lost = [e for e in events if e["event"] == "probe"]
    assert (made["code"], lost["code"]) == ("G38.2", "G38.4")
    # the drives' latch (0x60BA, then 0x60BB) to the count: the host's encoders, read a
    # TPDO1 or more after the edge, are up to 20 um further on per cycle
    assert made["tripped"] and made["trip_mm"][0] == pytest.approx(face_x, abs=0.0011)
    assert lost["tripped"] and lost["trip_mm"][0] == pytest.approx(face_x, abs=0.0011)
    # The host FIFO gives its frames back: the stop at Amax starts once the trip is seen (a
    # TPDO1 and a look of the motion loop later), not behind the FIFO's 100 ms of frames
    # (2 mm at 20 mm/s): under half of that, with the stop's own distance.
    for probe, sign in ((made, 1), (lost, -1)):
        over_mm = sign * (probe["stop_mm"][0] - probe["trip_mm"][0])
        assert 0.0 < over_mm < 20.0 * 0.050 + 20.0**2 / (2 * 2450.0)
    assert events[-1]["final_position_mm"]["x"] == pytest.approx(lost["trip_mm"][0], abs=0.0011)


def test_canopen_without_a_touch_probe_refuses_a_g38_before_moving(tmp_path: Path) -> None:
    program = tmp_path / "probe.nc"
    program.write_text("G21 G90 F300\nG0 X1\nG38.2 X20\nM2\n")
    with canopen_peer() as (_, path):
        done = subprocess.run([*CLI, "run", str(program), "--config", "canopen",
                               "--drive-option", f"channel={path}"], capture_output=True,
                              text=True, timeout=120, stdin=subprocess.DEVNULL, cwd=REPO)
    assert done.returncode == 2, done.stderr
    assert "canopen drive has no probe input" in done.stderr and "touch_probe" in done.stderr


def test_the_io_demo_runs_on_three_canopen_drives_with_their_touch_probe(tmp_path: Path) -> None:
    """nc_programs/io_demo.nc (spindle, coolant, outputs, two tool changes, a probe) on the
    mill's axes as three CiA 402 drives in the peer process."""
    mill = yaml.safe_load((REPO / "config" / "xyz_mill.yaml").read_text())
    mill["drive"] = yaml.safe_load((REPO / "config" / "canopen.yaml").read_text())["drive"]
    mill["drive"]["options"] |= {"node_ids": [1, 2, 3], "counts_per_mm": [1000.0] * 3,
                                 "touch_probe": True, **LOADED_CANOPEN}
    mill["sample_period_s"] = 0.002  # 3 drives through a pty: half the frames of 1 ms
    config = tmp_path / "mill_canopen.yaml"
    config.write_text(yaml.safe_dump(mill))
    tools = tmp_path / "tool.tbl"
    tools.write_text("T1 P1 Z5 D6\nT2 P2 Z12 D3\n")
    record = tmp_path / "outputs.json"
    with io_peer("canopen", config, "probe_workpiece_mm=-50,-50,-50,50,50,0",
                 f"outputs_file={record}") as path:
        events = run_confirming_tools([*CLI, "run", str(REPO / "nc_programs" / "io_demo.nc"),
                                       "--config", str(config), "--tools", str(tools),
                                       "--drive-option", f"channel={path}", "--json"])
    kinds = [(e["event"], e.get("line")) for e in events if e["event"] != "output"]
    assert kinds == [("start", None), ("tool", 8), ("probe", 16), ("tool", 24), ("done", 30)]
    (probe,) = [e for e in events if e["event"] == "probe"]
    # the drives' latch: the work's top face at machine Z0, to Z's count
    assert probe["tripped"] and probe["trip_mm"][2] == pytest.approx(0.0, abs=0.0011)
    assert events[-1]["final_position_mm"] == {"x": 25.0, "y": 25.0, "z": 32.0}
    # at the peer: spindle, coolant and P0 off at the end, E0 (channel 1) as the program left it
    held = read_outputs(str(record))
    assert held is not None and held["bits"] == 0 and held["analog"][1] == 2.5
