"""cncd jobs on a loaded machine PC: late cycles, lowest card FIFO and underruns of
a run while stress-ng keeps CPU hogs, I/O and memory hogs busy, a fresh daemon per run.

    python bench/loaded_pc.py [--runs 5] [--program nc_programs/butterfly.nc] [--unprivileged]

--unprivileged starts cncd without CAP_SYS_NICE (setpriv, as root): ordinary scheduling.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
from daemon_helpers import CNCCTL, start_cncd, stop  # noqa: E402

LOAD = ["stress-ng", "--cpu", "4", "--io", "2", "--vm", "2", "--vm-bytes", "256M"]
NO_SYS_NICE = ["setpriv", "--inh-caps=-sys_nice", "--bounding-set=-sys_nice"]


def one_run(program: str, wrapper: list[str] | None) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        daemon = start_cncd(Path(tmp), wrapper=wrapper)
        try:
            subprocess.run([*CNCCTL, "reset", "--socket", daemon.socket_path],
                           capture_output=True, timeout=30, check=True)
            done = subprocess.run([*CNCCTL, "run", program, "--json", "--socket",
                                   daemon.socket_path], capture_output=True, text=True,
                                  timeout=120)
            return json.loads(done.stdout.splitlines()[-1])
        finally:
            stop(daemon)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--program", default=str(REPO / "nc_programs" / "butterfly.nc"))
    ap.add_argument("--unprivileged", action="store_true")
    args = ap.parse_args()
    if shutil.which("stress-ng") is None:
        sys.exit("needs stress-ng")
    load = subprocess.Popen([*LOAD, "--timeout", f"{args.runs * 20 + 10}s"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        for _ in range(args.runs):
            r = one_run(args.program, NO_SYS_NICE if args.unprivileged else None)
            sched = (r.get("scheduling") or {}).get("summary", r.get("realtime"))
            print(f"{r['event']:6} motion {r['motion_time_s']:.3f} s  late cycles "
                  f"{r['late_cycles']:4}  lowest FIFO {r['min_fifo_ms']:5.1f} ms  underruns "
                  f"{r['underruns']}  {r['message'][:50]}  [{str(sched)[:60]}]", flush=True)
    finally:
        load.terminate()  # by its pid: the stress-ng we started
        load.wait()
    return 0


if __name__ == "__main__":
    sys.exit(main())
