"""Runs with probes (G38.2-G38.5): the program in stretches that each end at a probe.

A probe ends its move where the probe trips, so nothing after it can be planned before it has
run: the interpreter reads no further than a probe without its result (a barrier,
controller/probe.py), the stretch runs, the motion loop watches the probe input on the probe's
line and, once it trips, stops along the path at Amax (the abort's stop). The next stretch
reads the program again from its first line with the results known and yields from the line
after the probe on, from where the machine came to rest; #5061-#5063 and #5070 are set there.
The results are kept in the order the probes ran, and a stretch yields from after the last
one run: a probe line in a loop (or a subprogram called again) runs once per pass.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

from controller.config import MachineConfig
from controller.io_events import T_DECIMALS, io_event
from controller.motion.loop import ESTOP_KEEP_MS
from controller.motion.types import MotionProgress, MotionResult, Outcome
from controller.probe import ProbeResult, ProbeResults
from controller.runtime.current_run import CurrentRun
from controller.runtime.processes import Runtime, RuntimeOptions
from drivers.base import Drive
from drivers.errors import DriveError
from drivers.probe_latch import ProbeLatch

TRIPPED_BY_PROBE = "the probe tripped"
# Left in the card when a trip takes the rest back, as the e-stop keeps: 2 frames (2 ms) ran
# the serial card dry under two CPU hogs in 4 probes of 16 (an underrun fault at the probe);
# a probe's latched trip does not depend on it, its overtravel grows by 4 ms of its feed.
PROBE_KEEP_MS = ESTOP_KEEP_MS


class ProbeWatch:
    """Watches the probe input while the motion loop executes a probe's line (`lines`: line ->
    G38.x). On the trip it notes the encoder position and asks the stop along the path."""

    def __init__(self, lines: dict[int, str], drive: Drive, config: MachineConfig,
                 start_mm: tuple[float, float, float]) -> None:
        self.lines, self.drive, self.config, self.start_mm = lines, drive, config, start_mm
        self.line: int | None = None  # the probe line reached in this stretch
        self.tripped = False
        self.trip_mm: tuple[float, float, float] | None = None
        self.error: str | None = None

    def wrap(self, inner: Callable[[], str | None],
             controller: Callable[[], Any]) -> Callable[[], str | None]:
        """The runtime's watch (dead processes) with the probe watched after it."""
        def watch() -> str | None:
            problem = inner()
            if problem is None:
                self._check(controller())
            return problem
        return watch

    def _check(self, ctrl: Any) -> None:
        if ctrl is None or self.tripped or self.error is not None:
            return
        line = ctrl.figures.line
        code = self.lines.get(line)
        if code is None:
            return
        contact = self.drive.probe_input()
        toward = code in ("G38.2", "G38.3")
        if contact is None:
            self._fail(ctrl, f"line {line}: {code}: the drive has no probe input")
        elif self.line is None and contact == toward:  # LinuxCNC refuses it at the start
            self.line = line
            self._fail(ctrl, f"line {line}: {code}: the probe is already "
                             f"{'in contact' if toward else 'out of contact'}")
        elif contact == toward:
            self.line, self.tripped = line, True
            self.trip_mm = self._encoder_mm(ctrl)
            _take_back(ctrl)
            ctrl.keep_outputs_at_abort = True  # spindle, coolant, outputs go on after it
            ctrl.request_abort(f"{TRIPPED_BY_PROBE} at line {line}")
        else:
            if self.line is None:
                self._arm(ctrl, line, code, toward)
            self.line = line

    def _arm(self, ctrl: Any, line: int, code: str, toward: bool) -> None:
        """A drive that latches the edge (CANopen's touch probe) is armed as its G38 move
        starts: an edge before it (a move that brushes the work) is not the probe's."""
        if isinstance(self.drive, ProbeLatch):
            try:
                self.drive.arm_probe(toward)
            except DriveError as exc:
                self._fail(ctrl, f"line {line}: {code}: arming the probe failed: {exc}")

    def latched_trip_mm(self) -> tuple[float, float, float] | None:
        """The trip point the drives latched (after the stretch, at rest), None from a drive
        without a latch or one that latched nothing (then the encoders' at the trip stands)."""
        if not self.tripped or not isinstance(self.drive, ProbeLatch):
            return None
        pulses = self.drive.probe_latch_pulses()
        return None if pulses is None else self._xyz_mm(pulses)

    def _fail(self, ctrl: Any, message: str) -> None:
        self.error = message
        ctrl.request_abort(message)

    def _encoder_mm(self, ctrl: Any) -> tuple[float, float, float]:
        """Where the encoders are as the trip is seen (machine mm, Z of the start on a table
        without Z): read just after the probe input, not the cycle's feedback from before it
        (the card may have clocked on in between, and the input then showed contact where
        that feedback stood short of the face). A failed read keeps the cycle's."""
        try:
            _, enc = self.drive.position_counts()
        except DriveError:
            enc = ctrl.figures.last_enc
        return self._xyz_mm(enc)

    def _xyz_mm(self, pulses: Any) -> tuple[float, float, float]:
        xyz = list(self.start_mm)
        for i, axis in enumerate(self.config.axes):
            xyz["xyz".index(axis.name)] = float(pulses[i]) * axis.pulse_mm
        return xyz[0], xyz[1], xyz[2]


def _take_back(ctrl: Any) -> None:
    """The frames the card has queued beyond PROBE_KEEP_MS are taken back (where the drive
    can), as the e-stop does: the abort's stop along the path at Amax then starts that long
    after the trip, not behind the whole card FIFO (100 ms of the probe's feed further on)."""
    ctrl.take_back_beyond_ms(PROBE_KEEP_MS)


class ProbeRun(CurrentRun):
    """The whole program, a stretch (a Runtime) per probe, on `drive` (open, kept open):
    operator requests go to the stretch now running (the override to every one), an abort
    asked between two stretches stops the next at once; every probe's result goes to
    on_event as a `probe` event. Used as a Runtime is (run, request_*, controller)."""

    def __init__(self, path: str, config: MachineConfig, options: RuntimeOptions,
                 drive: Drive, lines: dict[int, str],
                 on_event: Callable[[dict[str, Any]], None]) -> None:
        self.path, self.config, self.drive, self.lines = path, config, drive, lines
        self.on_event = on_event
        self.clock = _RunClock(options.on_progress)  # one time line over the stretches
        self.options = replace(options, on_progress=self.clock.progress
                               if options.on_progress else None,
                               on_event=self.clock.event(options.on_event))
        super().__init__()
        self.override_pct = 100.0

    @property
    def controller(self) -> Any:
        return self.current.controller if self.current is not None else None

    def set_feed_override(self, percent: float) -> None:
        self.override_pct = percent  # the next stretches start with it
        super().set_feed_override(percent)

    def run(self) -> MotionResult:
        results = ProbeResults(barrier=True)
        start = self.drive.commanded_xyz_mm()
        last_line = _line_count(self.path)
        while True:
            watch = ProbeWatch(self.lines, self.drive, self.config, start)
            runtime = Runtime(self.path, self.config, replace(
                self.options, drive=self.drive, keep_drive_open=True,
                start_mm=self.options.start_mm or start, from_line=None,
                probes=ProbeResults(list(results.by_index), barrier=True,
                                    resume_after=len(results.by_index)), probe_watch=watch))
            runtime.set_feed_override(self.override_pct)
            self.current = runtime
            if self.abort is not None:
                runtime.request_abort(self.abort)
            result = runtime.run()
            t_s = self.clock.stretch_done(runtime)
            if watch.line is None or watch.error is not None \
                    or result.outcome is Outcome.FAULT \
                    or (result.outcome is Outcome.ABORTED and not watch.tripped):
                return result
            stop = self.drive.commanded_xyz_mm()
            line, code = watch.line, self.lines[watch.line]
            trip = watch.latched_trip_mm() or watch.trip_mm or stop
            probe = ProbeResult(line, watch.tripped, trip, stop)
            results.by_index.append(probe)
            self.on_event(io_event("probe", t_s, line, code=code, **{
                k: v for k, v in probe.describe().items() if k != "line"}))
            if not probe.tripped and code in ("G38.2", "G38.4"):
                return replace(result, outcome=Outcome.ABORTED, message=(
                    f"line {line}: {code}: the probe move ended without "
                    f"{'making' if code == 'G38.2' else 'losing'} contact"))
            if line >= last_line:
                return replace(result, outcome=Outcome.DONE, message="")


class _RunClock:
    """The run's time over its stretches: each runtime's clock starts at 0, so progress is
    passed on with the time of the stretches before it added (a view that paces its reports
    by time would hold them back otherwise), and events are timed on the same line."""

    def __init__(self, inner: Callable[[MotionProgress], None] | None) -> None:
        self.inner = inner
        self.before_s = 0.0

    def progress(self, p: MotionProgress) -> None:
        if self.inner is not None:
            self.inner(replace(p, elapsed_s=p.elapsed_s + self.before_s))

    def event(self, inner: Callable[[dict[str, Any]], None] | None
              ) -> Callable[[dict[str, Any]], None] | None:
        """The motion loop's events (output changes) timed on the run's line."""
        if inner is None:
            return None

        def on_event(e: dict[str, Any]) -> None:
            t_s = e.get("t_s")
            inner(e if t_s is None else e | {"t_s": round(t_s + self.before_s, T_DECIMALS)})
        return on_event

    def stretch_done(self, runtime: Runtime) -> float:
        """The run's time at the end of this stretch."""
        ctrl = runtime.controller
        self.before_s += ctrl.pacer.elapsed_s() if ctrl is not None else 0.0
        return self.before_s


def _line_count(path: str) -> int:
    with open(path, "rb") as fh:
        return sum(1 for _ in fh)
