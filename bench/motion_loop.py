"""The motion loop alone in virtual time, on a reference stream recorded once: CPU and results.

    python bench/motion_loop.py PROGRAM [--runs N] [--code DIR]

The program's reference rows are planned once (by this process, with the shipped config) and
kept beside it as PROGRAM.rows.npy; each run then feeds them to a MotionController on the sim
card clocked in virtual time, as `cncctl run --virtual-time` does in its motion process, but
with no generator or interpreter process to wait for or ask about. Per run: the loop's CPU
(process time), the motion time, and hashes of the result and of every progress report (the
same hashes from two trees: the same run). Run under `valgrind --tool=callgrind` it counts the
loop's instructions (plus some 0.9 G of imports and planning's cache, the same for any tree).
--code DIR imports the controller from another checkout (a before/after comparison).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]


class RowSource:
    """A RefSource over rows in memory, finished from the start (the producer is done)."""

    def __init__(self, rows: Any, finished: Any) -> None:
        self.rows, self.pos, self.finished = rows, 0, finished

    def read(self, max_rows: int) -> Any:
        out = self.rows[self.pos : self.pos + max_rows]
        self.pos += len(out)
        return out

    def state(self) -> tuple[Any, str]:
        return self.finished, ""

    def total_rows(self) -> int:
        return len(self.rows)

    def primed(self) -> bool:
        return True


def recorded_rows(program: Path, config: Any) -> Any:
    """The program's ring rows (controller/motion/source.py), planned once and kept."""
    import numpy as np

    path = program.with_name(program.name + ".rows.npy")
    if not path.exists():
        from controller.generator.plan import generate_reference
        from controller.interpreter.program import read_program
        from controller.motion.source import SyncMarks

        marks = SyncMarks()
        rows = [
            marks.rows(c)[0] for c in generate_reference(read_program(str(program), config), config)
        ]
        np.save(path, np.vstack(rows))
    return np.load(path)


def one_run(config: Any, rows: Any) -> tuple[float, str, str, int]:
    """CPU of one loop, its result's hash, its progress reports' hash and their count."""
    from controller.motion.loop import MotionController
    from controller.motion.pacing import VirtualPacer
    from controller.motion.source import SourceState
    from controller.motion.types import MotionSettings
    from controller.runtime.processes import build_drive, open_drive

    drive = build_drive(config, True)
    open_drive(drive)
    settings = MotionSettings.from_config(config)
    pacer = VirtualPacer(
        settings.cycle_frames,
        config.sample_period_s,
        drive.advance,
        advance_until=drive.advance_until,
    )
    reports = hashlib.sha1()
    count = [0]

    def progress(p: Any) -> None:
        count[0] += 1
        reports.update(repr(p).encode())

    loop = MotionController(
        config, drive, RowSource(rows, SourceState.FINISHED), pacer, settings, on_progress=progress
    )
    t0_s = time.process_time()
    result = loop.run()
    cpu_s = time.process_time() - t0_s
    drive.close()
    figures = asdict(result)
    figures.pop("extra", None)
    digest = hashlib.sha1(json.dumps(figures, sort_keys=True, default=str).encode())
    return cpu_s, digest.hexdigest()[:12], reports.hexdigest()[:12], count[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("program", type=Path)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--code", default=str(REPO), help="checkout whose controller is run")
    args = parser.parse_args()
    sys.path.insert(0, str(Path(args.code).resolve()))
    from controller.config import load_config
    from controller.servo.prediction import axis_servos

    config = load_config(None)
    rows = recorded_rows(args.program.resolve(), config)
    axis_servos(config)  # built before the loop, as the runtime does before its fork
    motion_s = len(rows) * config.sample_period_s
    for _ in range(args.runs):
        cpu_s, result, reports, n = one_run(config, rows)
        print(
            f"motion {motion_s:.1f} s  loop CPU {cpu_s:.3f} s  "
            f"({cpu_s / motion_s * 1e3:.2f} ms per s of motion)  result {result}  "
            f"progress {n} {reports}",
            flush=True,
        )


if __name__ == "__main__":
    main()
