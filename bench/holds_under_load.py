"""Feed holds through cncd under load: how many holds ran the card dry (an underrun fault).

One cncd owns the drive (the sim card, or the serial card's simulated peer in its own process
on a pseudo-terminal); N short jobs (a 40 mm line at 20 mm/s, out and back) are each held at
a random moment through `cncctl hold` once moving, resumed once HELD, and run to their end.
The load is `stress-ng --cpu N` (started and stopped here by its process group):

    python bench/holds_under_load.py [--holds 40] [--backend sim|serial] [--cpu 2]
"""

from __future__ import annotations

import argparse
import json
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "bench"))
sys.path.insert(0, str(REPO / "tests"))
from daemon_helpers import CNCCTL, start_cncd, stop  # noqa: E402
from jobs_under_load import start_peer, stop_load, write_config  # noqa: E402

OUT = "G21 G90 G64 F1200\nG1 X40 Y5\nM2\n"
BACK = "G21 G90 G64 F1200\nG1 X0 Y0\nM2\n"


def wait_state(daemon: Any, state: str, timeout_s: float = 20.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        now = daemon.status()["state"]
        if now == state:
            return True
        if now in ("IDLE", "FAULT"):
            return False
        time.sleep(0.02)
    return False


def one_hold(daemon: Any, program: Path, rng: random.Random) -> dict[str, Any]:
    run = subprocess.Popen(
        [*CNCCTL, "run", str(program), "--json", "--socket", daemon.socket_path],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
    )
    try:
        assert run.stdout is not None
        for line in run.stdout:  # moving: then a hold at a random moment of the line
            if json.loads(line).get("executed_s", 0) > 0.05:
                break
        time.sleep(rng.uniform(0.0, 0.6))
        held = daemon.cncctl("hold").returncode == 0 and wait_state(daemon, "HELD")
        if held:
            daemon.cncctl("resume")
        out, err = run.communicate(timeout=60)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
    events = [json.loads(x) for x in out.splitlines() if x.startswith("{")]
    final = (
        events[-1]
        if events
        else {
            "event": "none",
            "message": f"exit {run.returncode}: {err.strip()}",
        }
    )
    return {
        "held": held,
        "event": final.get("event"),
        "underruns": final.get("underruns", 0),
        "message": final.get("message", ""),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--holds", type=int, default=40)
    ap.add_argument("--backend", choices=("sim", "serial"), default="sim")
    ap.add_argument("--cpu", type=int, default=2, help="stress-ng CPU hogs (0: quiet)")
    args = ap.parse_args()
    rng = random.Random(1)
    folder = Path(tempfile.mkdtemp(prefix="phcnc-holds-"))
    programs = [folder / "out.nc", folder / "back.nc"]
    programs[0].write_text(OUT)
    programs[1].write_text(BACK)
    peer, device = start_peer(args.backend)
    hog = None
    rows = []
    try:
        daemon = start_cncd(folder, "--config", str(write_config(args.backend, device, folder)))
        try:
            assert daemon.cncctl("reset").returncode == 0
            if args.cpu:
                hog = subprocess.Popen(
                    ["stress-ng", "--cpu", str(args.cpu), "--quiet"], start_new_session=True
                )
                time.sleep(2.0)
            for k in range(args.holds):
                rows.append(one_hold(daemon, programs[k % 2], rng))
                if rows[-1]["event"] != "done":
                    print(f"  hold {k}: {rows[-1]['event']} {rows[-1]['message']}", file=sys.stderr)
                    daemon.cncctl("reset")
            load = open("/proc/loadavg").read().split()[0]
        finally:
            stop_load(hog)
            stop(daemon)
    finally:
        if peer is not None:
            peer.kill()
            peer.wait()
    held = sum(r["held"] for r in rows)
    faults = sum(r["event"] != "done" for r in rows)
    print(
        f"{args.backend}, stress-ng --cpu {args.cpu} (load average {load}): {len(rows)} jobs, "
        f"{held} held, {faults} faults, {sum(r['underruns'] for r in rows)} underruns"
    )


if __name__ == "__main__":
    main()
