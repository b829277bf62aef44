"""Machine outputs through cncd, from outside: a real daemon, `cncctl run --json` relaying one
line per output change, `cncctl status` showing the outputs, and the e-stop and an abort
leaving them in their safe state."""

from __future__ import annotations

import json
from pathlib import Path

import yaml
from daemon_helpers import REPO, running_cncd, start_run, wait_moving

PROGRAM = "G21 G90\nM3 S1000\nM8\nM62 P0\nM67 E0 Q4\nG1 X5 F600\n"  # no M2: they stay on


def mill(tmp_path: Path) -> Path:
    data = yaml.safe_load((REPO / "config" / "xyz_mill.yaml").read_text())
    data["io"]["spindle"]["spin_up_s"] = 0.1
    path = tmp_path / "mill.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_run_relays_output_events_and_status_shows_them_until_the_estop(tmp_path: Path) -> None:
    prog = tmp_path / "outputs.nc"
    prog.write_text(PROGRAM)
    with running_cncd(tmp_path, "--config", str(mill(tmp_path))) as d:
        assert d.cncctl("reset").returncode == 0
        done = d.cncctl("run", str(prog), "--json")
        assert done.returncode == 0, done.stderr
        events = [json.loads(line) for line in done.stdout.splitlines()]
        outputs = [(e["line"], e["name"], e["value"]) for e in events
                   if e["event"] == "output"]
        # M62 and M67 go with the next move: at its first sample, line 6
        assert outputs == [(2, "spindle_rpm", 1000.0), (2, "spindle", "cw"),
                           (3, "coolant_flood", True), (6, "digital_0", True),
                           (6, "analog_0", 4.0)]
        assert events[-1]["event"] == "done"
        assert d.status()["outputs"] == {
            "spindle": "cw", "spindle_rpm": 1000.0, "coolant_mist": False,
            "coolant_flood": True, "digital": [True, False], "analog": [4.0]}
        text = d.cncctl("status").stdout
        assert ("outputs: spindle cw 1000 rpm, coolant flood, digital P0 on P1 off, "
                "analog E0 4") in text
        assert d.cncctl("estop").returncode == 0
        assert d.status()["outputs"] == {
            "spindle": "off", "spindle_rpm": 1000.0, "coolant_mist": False,
            "coolant_flood": False, "digital": [False, False], "analog": [0.0]}
        assert "outputs: spindle off, coolant off" in d.cncctl("status").stdout


def test_an_abort_mid_job_sets_the_safe_state(tmp_path: Path) -> None:
    prog = tmp_path / "long.nc"
    prog.write_text("G21 G90\nM4 S700\nM7\nM64 P1\nG1 X60 F300\nM2\n")  # 12 s of cutting
    with running_cncd(tmp_path, "--config", str(mill(tmp_path))) as d:
        d.cncctl("reset")
        run = start_run(d, prog)
        try:
            wait_moving(run, after_s=1.0)  # cutting: P1 was set before the move
            assert d.status()["outputs"]["spindle"] == "ccw"
            assert d.cncctl("abort").returncode == 0
            out, _ = run.communicate(timeout=20)
        finally:
            run.kill()
        events = [json.loads(line) for line in out.splitlines()]
        assert run.returncode == 4 and events[-1]["event"] == "aborted"
        safe = [(e["name"], e["value"]) for e in events if e.get("safe")]
        assert safe == [("spindle", "off"), ("coolant_mist", False), ("digital_1", False)]
        status = d.status()
        assert status["state"] == "IDLE"
        assert status["outputs"]["spindle"] == "off" and status["outputs"]["digital"] == [
            False, False]
