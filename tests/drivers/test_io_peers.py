"""Machine I/O through the simulated peers in their own processes (`cncctl simdrive serial` on a
pty, `cncctl simdrive canopen` behind a fake slcan adapter) and `cncctl run --json` in another:
the outputs the peer holds (read back from the peer's outputs_file), one JSON event line per
change, the safe state after a limit switch or the e-stop input, and which input stopped it."""

from __future__ import annotations

import json
import select
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
import yaml
from daemon_helpers import LOADED_LINK, open_switch

from drivers.io_peer import read_outputs

REPO = Path(__file__).resolve().parents[2]
CLI = [sys.executable, "-m", "controller.operator.cli"]
IO = yaml.safe_load((REPO / "config" / "xyz_mill.yaml").read_text())["io"]
# xyz_mill's io map: spindle on bit 0, reverse 1, speed channel 0; mist 2, flood 3; P0 -> bit 4,
# P1 -> bit 5; E0 -> channel 1.
PROGRAM = """G21 G90
M4 S1200
M7
G1 X5 F600
M62 P0
M68 E0 Q3.25
G1 X10 Y2
M5 M9
M2
"""
LONG = "G21 G90\nM3 S1000\nM8\nM64 P1\nG1 X80 F300\nM2\n"  # 16 s of cutting
LINK = LOADED_LINK  # the subject here is the I/O, not the link
PORT = {"serial": "port", "canopen": "channel"}


def config_with_io(tmp_path: Path, backend: str) -> Path:
    data = yaml.safe_load((REPO / "config" / f"{backend}.yaml").read_text())
    data["io"] = IO
    data["io"]["spindle"]["spin_up_s"] = 0.2
    path = tmp_path / f"{backend}_io.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@contextmanager
def peer(backend: str, config: Path, *options: str) -> Iterator[str]:
    """The simulated hardware in its own process; killed by its pid on the way out."""
    args = [*CLI, "simdrive", backend, "--config", str(config)]
    for option in options:
        args += ["--option", option]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=REPO)
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 20.0)
        assert ready, "simdrive printed no device path within 20 s"
        path = proc.stdout.readline().strip()  # type: ignore[union-attr]
        assert path.startswith("/dev/"), (path, proc.stderr.read() if proc.poll() else "")  # type: ignore[union-attr]
        yield path
    finally:
        proc.kill()
        proc.wait(timeout=10)


def run(backend: str, config: Path, port: str, text: str, tmp_path: Path,
        during: Any = None) -> tuple[int, list[dict[str, Any]], str]:
    """`cncctl run --json` in its own process: (exit code, every JSON line, stderr);
    during(event) sees each line as it comes."""
    prog = tmp_path / "prog.nc"
    prog.write_text(text)
    proc = subprocess.Popen([*CLI, "run", str(prog), "--config", str(config), "--json",
                             "--drive-option", f"{PORT[backend]}={port}", *LINK[backend]],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=REPO, stdin=subprocess.DEVNULL)
    events = []
    try:
        for line in proc.stdout:  # type: ignore[union-attr]
            if line.startswith("{"):
                events.append(json.loads(line))
                if during is not None:
                    during(events[-1])
        code = proc.wait(timeout=60)
        return code, events, proc.stderr.read()  # type: ignore[union-attr]
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)


def outputs_of(events: list[dict[str, Any]]) -> list[tuple[int, str, Any, bool]]:
    return [(e["line"], e["name"], e["value"], bool(e.get("safe")))
            for e in events if e["event"] == "output"]


def wait_file(path: Path, check: Any, timeout_s: float = 5.0) -> dict[str, Any]:
    deadline_s = time.monotonic() + timeout_s
    while True:
        got = read_outputs(str(path))
        if got is not None and check(got):
            return got
        assert time.monotonic() < deadline_s, f"the peer's outputs stayed {got}"
        time.sleep(0.02)


@pytest.mark.parametrize("backend", ["serial", "canopen"])
def test_outputs_reach_the_peer_and_each_change_is_a_json_line(tmp_path: Path,
                                                               backend: str) -> None:
    config = config_with_io(tmp_path, backend)
    record = tmp_path / "outputs.json"
    seen: list[dict[str, Any] | None] = []

    def during(event: dict[str, Any]) -> None:
        if event["event"] == "output" and event["name"] == "analog_0":
            seen.append(read_outputs(str(record)))  # the peer has them before the line
    with peer(backend, config, f"outputs_file={record}") as port:
        code, events, err = run(backend, config, port, PROGRAM, tmp_path, during)
    assert code == 0, err
    assert outputs_of(events) == [
        (2, "spindle_rpm", 1200.0, False), (2, "spindle", "ccw", False),
        (3, "coolant_mist", True, False), (5, "digital_0", True, False),
        (6, "analog_0", 3.25, False), (8, "spindle", "off", False),
        (8, "coolant_mist", False, False)]
    lines = [e for e in events if e["event"] == "output"]
    assert all(set(e) == {"event", "t_s", "line", "name", "value"} for e in lines)
    assert [e["t_s"] for e in lines] == sorted(e["t_s"] for e in lines)
    # While E0 was set: spindle on and reversed at 1200 rpm, mist, P0 (bits 0, 1, 2, 4).
    assert seen == [{"bits": 0b10111, "analog": [1200.0, 3.25, 0.0, 0.0]}]
    # At the end (M2 stopped spindle and coolant): P0 and E0 stay as the program left them.
    assert read_outputs(str(record)) == {"bits": 1 << 4, "analog": [0.0, 3.25, 0.0, 0.0]}
    assert events[-1]["outputs"]["digital"] == [True, False]


@pytest.mark.parametrize("backend", ["serial", "canopen"])
@pytest.mark.parametrize("switch", ["limit", "estop"])
def test_an_input_stops_the_job_names_itself_and_leaves_the_outputs_safe(
        tmp_path: Path, backend: str, switch: str) -> None:
    config = config_with_io(tmp_path, backend)
    record = tmp_path / "outputs.json"
    trip = tmp_path / "input"
    option = "limit_input_file" if switch == "limit" else "estop_input_file"
    tripped_at: list[float] = []

    def during(event: dict[str, Any]) -> None:
        if event["event"] == "progress" and event["line"] == 5 and event["executed_s"] > 1.5 \
                and not tripped_at:
            open_switch(trip, "y-")  # the limit switch's name (the e-stop input ignores it)
            tripped_at.append(event["executed_s"])
    with peer(backend, config, f"outputs_file={record}", f"{option}={trip}") as port:
        code, events, err = run(backend, config, port, LONG, tmp_path, during)
    final = events[-1]
    if switch == "limit":
        assert code == 3 and final["event"] == "fault", (code, final, err)
        assert final["message"] == "hard limit: Y- limit switch tripped"
    else:
        assert code == 4 and final["event"] == "aborted", (code, final, err)
        assert final["message"] == "e-stop input on the drive tripped"
    # It stopped mid-cut (the 80 mm line at 5 mm/s was far from done), spindle and coolant off
    # and P1 back to its safe value, at the peer and in the events.
    assert final["final_position_mm"]["x"] < 40.0
    assert wait_file(record, lambda got: got["bits"] == 0)["analog"] == [0.0] * 4
    assert [(n, v) for _, n, v, safe in outputs_of(events) if safe] == [
        ("spindle", "off"), ("coolant_flood", False), ("digital_1", False)]


@pytest.mark.parametrize("backend", ["serial", "canopen"])
def test_m62_goes_with_the_next_move_on_the_peers_without_a_stop(tmp_path: Path,
                                                                 backend: str) -> None:
    """The host sets it once the move's first frame is fed back as run (the peers have no
    output timed with a frame): the job blends through it as if it were not there."""
    config = config_with_io(tmp_path, backend)
    record = tmp_path / "outputs.json"
    # back to X0 Y0 at the end: the plain program starts where this one did
    synced = "G21 G90 G64 F1200\nG1 X10\nM62 P0\nG1 X20 Y5\nG1 X30\nG0 X0 Y0\nM2\n"
    seen: list[dict[str, Any] | None] = []

    def during(event: dict[str, Any]) -> None:
        if event["event"] == "output":
            seen.append(read_outputs(str(record)))  # reported once the peer holds it
    with peer(backend, config, f"outputs_file={record}") as port:
        code, events, err = run(backend, config, port, synced, tmp_path, during)
        assert code == 0, (err, events[-1])
        code, plain, err = run(backend, config, port, synced.replace("M62 P0\n", ""),
                               tmp_path)
        assert code == 0, err
    assert outputs_of(events) == [(4, "digital_0", True, False)]
    assert seen == [{"bits": 1 << 4, "analog": [0.0] * 4}]
    # no stop at it: planned as the program without it
    assert events[-1]["planned_time_s"] == plain[-1]["planned_time_s"]


AT_SPEED_INPUT = {"serial": "serial card, status io bit 9 AT_SPEED",
                  "canopen": "CANopen node 1, 0x60FD bit 16"}


@pytest.mark.parametrize("backend", ["serial", "canopen"])
def test_the_peers_at_speed_input_holds_the_job_at_the_spindle_start(tmp_path: Path,
                                                                      backend: str) -> None:
    """The peer's spindle reaches speed 0.5 s after the start (its option): within a 3 s
    time-out the job goes on; within 0.2 s it faults naming the input, the outputs safe."""
    data = yaml.safe_load(config_with_io(tmp_path, backend).read_text())
    data["io"]["spindle"].update(spin_up_s=0.0, at_speed_input=True)
    configs = {}
    for timeout_s in (3.0, 0.2):
        data["io"]["spindle"]["at_speed_timeout_s"] = timeout_s
        configs[timeout_s] = tmp_path / f"at_speed_{timeout_s:g}.yaml"
        configs[timeout_s].write_text(yaml.safe_dump(data))
    record = tmp_path / "outputs.json"
    program = "G21 G90\nM3 S1000\nG1 X2 F600\nG0 X0\nM2\n"
    with peer(backend, configs[3.0], f"outputs_file={record}", "spindle_spinup_s=0.5") as port:
        code, events, err = run(backend, configs[3.0], port, program, tmp_path)
        assert code == 0 and events[-1]["event"] == "done", (err, events[-1])
        code, events, err = run(backend, configs[0.2], port, program, tmp_path)
    final = events[-1]
    assert code == 3 and final["event"] == "fault", (code, final, err)
    assert final["message"] == (f"line 2: spindle not at speed within 0.2 s (input: "
                                f"{AT_SPEED_INPUT[backend]}, io.spindle.at_speed_timeout_s)")
    assert set(final["final_position_mm"].values()) == {0.0} and final["position_known"]
    assert wait_file(record, lambda got: got["bits"] == 0)["analog"] == [0.0] * 4
