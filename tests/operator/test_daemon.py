"""cncd: sd_notify READY/WATCHDOG/STOPPING to a fake manager, a run request over the socket."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def test_daemon_notifies_serves_a_run_and_stops(tmp_path: Path) -> None:
    notify_path = str(tmp_path / "notify")
    manager = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    manager.bind(notify_path)
    manager.settimeout(20.0)
    messages: list[str] = []

    def drain() -> None:  # a manager that reads promptly, as systemd does
        while True:
            try:
                messages.append(manager.recv(4096).decode())
            except OSError:
                return
    ctl = str(tmp_path / "control.sock")
    program = tmp_path / "square.nc"
    program.write_text("G21 G90 F1200\nG1 X2 Y0\nG1 X2 Y2\nG1 X0 Y0\nM2\n")
    env = dict(os.environ, NOTIFY_SOCKET=notify_path, WATCHDOG_USEC="400000")
    proc = subprocess.Popen([sys.executable, "-m", "controller.operator.daemon", "--socket", ctl],
                            cwd=REPO, env=env)
    threading.Thread(target=drain, daemon=True).start()
    try:
        deadline = time.monotonic() + 20
        while "WATCHDOG=1" not in messages and time.monotonic() < deadline:
            time.sleep(0.05)
        assert messages[0].startswith("READY=1") and "WATCHDOG=1" in messages
        out = subprocess.run([sys.executable, "-m", "controller.operator.cli", "run", str(program),
                              "--daemon", ctl, "--virtual-time"], cwd=REPO,
                             capture_output=True, text=True, timeout=60)
        final = json.loads(out.stdout.splitlines()[-1])
        assert out.returncode == 0 and final["event"] == "done", out.stdout[-500:]
        assert final["final_position_mm"] == {"x": 0.0, "y": 0.0}
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
        time.sleep(0.1)
        assert "STOPPING=1" in messages and any(m.startswith("STATUS=running") for m in messages)
    finally:
        if proc.poll() is None:
            proc.kill()
        manager.close()
