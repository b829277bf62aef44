"""Machine I/O bench: how long setting the outputs takes on each backend's simulated peer, and
how soon a limit switch opened on the peer is seen by the host.

Each backend's peer runs in its own process (`cncctl simdrive serial|canopen`, on a pty) with
config/xyz_mill.yaml's `io` map; this process opens the drive and:

- sets the outputs N times, alternating two states that differ in every mapped output
  (Drive.set_outputs: the serial card's OUTPUTS frame and its status reply; the CiA 402
  drive's six SDO writes), timed from the call to its return: p50 / p99 / max;
- opens the peer's limit_input_file N times and times until Drive.limit_input() names the
  switch (polled every 1 ms, as the motion loop does each cycle): p50 / p99 / max.

    python bench/outputs.py [--n 50]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from controller.blocks import OutputChange  # noqa: E402
from controller.config import load_config  # noqa: E402
from drivers.registry import make_drive  # noqa: E402

PORT = {"serial": "port", "canopen": "channel"}
STATES = [
    (OutputChange("spindle", "cw"), OutputChange("spindle_rpm", 12000.0),
     OutputChange("coolant_flood", True), OutputChange("digital_0", True),
     OutputChange("analog_0", 5.0)),
    (OutputChange("spindle", "off"), OutputChange("spindle_rpm", 0.0),
     OutputChange("coolant_flood", False), OutputChange("digital_0", False),
     OutputChange("analog_0", 0.0)),
]


def config_file(backend: str, folder: Path) -> Path:
    data = yaml.safe_load((REPO / "config" / f"{backend}.yaml").read_text())
    data["io"] = yaml.safe_load((REPO / "config" / "xyz_mill.yaml").read_text())["io"]
    path = folder / f"{backend}_io.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def figures(samples_s: list[float]) -> str:
    ms = np.array(samples_s) * 1e3
    return (f"p50 {np.percentile(ms, 50):.2f} ms, p99 {np.percentile(ms, 99):.2f} ms, "
            f"max {ms.max():.2f} ms")


def bench(backend: str, n: int, folder: Path) -> dict[str, Any]:
    cfg = config_file(backend, folder)
    trip = folder / f"{backend}_limit"
    peer = subprocess.Popen([sys.executable, "-m", "controller.operator.cli", "simdrive",
                             backend, "--config", str(cfg), "--option",
                             f"limit_input_file={trip}"], cwd=REPO, stdout=subprocess.PIPE,
                            text=True)
    try:
        port = peer.stdout.readline().strip()  # type: ignore[union-attr]
        drive = make_drive(load_config(str(cfg)).with_drive_options({PORT[backend]: port}),
                           realtime=True)
        with drive:
            set_s = []
            for i in range(n):
                t0_s = time.perf_counter()
                drive.set_outputs(STATES[i % 2])
                set_s.append(time.perf_counter() - t0_s)
            seen_s = []
            for _ in range(n):
                t0_s = time.perf_counter()
                trip.write_text("x+")
                while drive.limit_input() is None:
                    time.sleep(0.001)
                seen_s.append(time.perf_counter() - t0_s)
                trip.unlink()
                while drive.limit_input() is not None:
                    time.sleep(0.001)
    finally:
        peer.kill()
        peer.wait(timeout=10)
    return {"set_outputs": figures(set_s), "limit_seen": figures(seen_s)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=50)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        for backend in ("serial", "canopen"):
            got = bench(backend, args.n, Path(folder))
            print(f"{backend}: set_outputs {got['set_outputs']}; limit switch seen after "
                  f"{got['limit_seen']}", flush=True)


if __name__ == "__main__":
    main()
