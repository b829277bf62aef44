"""What `cncctl run` shows: a rich progress bar, plain lines, or JSON lines."""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from typing import Any, TextIO

from controller.motion.types import MotionProgress, MotionResult, MotionState
from controller.operator.io_text import output_event_text
from controller.operator.words import axes_text, fields_text, pulses_text

MAX_MARKS = 4096  # file positions a ProgramLines keeps, whatever the program's length
SHOWN_CHARS = 256  # a line's text kept for the status line (it shows 32); the rest is skipped


class ProgramLines(Sequence[str]):
    """The program's lines for the status line (lines[i], i from 0; len()), read from the file
    when shown instead of held: a list of the whole program cost ~100 bytes a line in the motion
    process (`cncctl run` on a 1M-line program: 143 MB peak RSS, against 54 MB at 100k lines).

    Bounded whatever the length: at most MAX_MARKS file positions, one every `stride` lines
    (the stride doubles when there would be more), taken in one pass before the run; a lookup
    reads forward from the file's current line or the nearest position, so at most `stride`
    lines when it jumps, and only the lines since the last shown as a run moves on. Lines are
    counted as the interpreter counts them (UTF-8, universal newlines).
    """

    def __init__(self, path: str) -> None:
        self.path = path
        self.stride = 1
        self.marks: list[int] = []  # tell() of lines 0, stride, 2 stride, ...
        self.count = 0
        self._file: TextIO | None = None
        self._at = 0  # the line the open file is at
        self._last: tuple[int, str] = (-1, "")
        try:
            with self._open() as f:
                while True:
                    if self.count % self.stride == 0:
                        if len(self.marks) == MAX_MARKS:  # every other one goes; count is
                            del self.marks[1::2]  # MAX_MARKS (even) strides, a multiple of
                            self.stride *= 2  # the new stride
                        self.marks.append(f.tell())
                    if _read_line(f) is None:
                        break
                    self.count += 1
        except (OSError, ValueError):
            self.count = 0  # unreadable: no line text shown, as before

    def _open(self) -> TextIO:
        return open(self.path, encoding="utf-8-sig", errors="replace", newline=None)

    def __len__(self) -> int:
        return self.count

    def __getitem__(self, i: int) -> str:  # type: ignore[override]  (no slices)
        if not 0 <= i < self.count:
            raise IndexError(i)
        if self._last[0] != i:
            self._last = (i, self._lookup(i))
        return self._last[1]

    def _lookup(self, i: int) -> str:
        try:
            if self._file is None:
                self._file, self._at = self._open(), 0
            mark = i // self.stride
            if i < self._at or mark * self.stride > self._at:
                self._file.seek(self.marks[mark])
                self._at = mark * self.stride
            while self._at < i and _read_line(self._file) is not None:
                self._at += 1
            text = _read_line(self._file)
            self._at += 1
            return text or ""
        except (OSError, ValueError):  # the file went or changed since: no text
            self.close()
            return ""

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


def _read_line(f: TextIO) -> str | None:
    """The next line's first SHOWN_CHARS characters (None at the end): a huge line is skipped in
    pieces, never read whole."""
    text = f.readline(SHOWN_CHARS)
    if not text:
        return None
    rest = text
    while not rest.endswith("\n") and len(rest) == SHOWN_CHARS:
        rest = f.readline(SHOWN_CHARS)
    return text.rstrip("\n")


def result_summary(result: MotionResult) -> dict[str, Any]:
    """The final JSON object (issue 5): event done/fault/aborted plus the measured figures."""
    names = result.commanded_counts.keys()
    return {
        "event": result.outcome.value,
        "message": result.message,
        "line": result.line,
        "motion_time_s": round(result.motion_time_s, 4),
        "settling_time_s": round(result.settling_time_s, 4),
        "planned_time_s": round(result.planned_time_s, 4),
        "contour_error_um": {k: round(v, 3) for k, v in result.contour_error_um.items()},
        "following_error_um_max": round(result.following_error_um_max, 3),
        "underruns": result.underruns,
        "late_cycles": result.late_cycles,
        "min_fifo_ms": round(result.min_fifo_ms, 1),
        "pulses": {n: {"commanded": result.commanded_counts[n],
                       "executed": result.executed_counts[n]} for n in names},
        "final_position_mm": {k: round(v, 6) for k, v in result.final_position_mm.items()},
        "position_known": result.position_known,
        "time_to_first_motion_s": result.time_to_first_motion_s,
        "model_residual_um": result.model_residual_um,
        **({"model_warning": result.model_warning} if result.model_warning else {}),
        **{k: v for k, v in result.extra.items() if k != "events"},  # each a line already
    }


def _settling_text(s: dict[str, Any]) -> str:
    """The settling after the motion time (a daemon of an older version may not send it)."""
    if "settling_time_s" not in s:
        return ""
    return f" then settling {s['settling_time_s']:.3f} s"


class JsonView:
    """One JSON object per line: start, progress (every 0.5 s), fault/abort notices, final."""

    def __init__(self, out: TextIO | None = None, every_s: float = 0.5) -> None:
        self.out, self.every_s, self._next_s = out or sys.stdout, every_s, 0.0

    def _emit(self, obj: dict[str, Any]) -> None:
        self.out.write(json.dumps(obj) + "\n")
        self.out.flush()

    def event(self, event: str, **fields: Any) -> None:
        self._emit({"event": event, **fields})

    def progress(self, p: MotionProgress) -> None:
        if p.elapsed_s < self._next_s:
            return
        self._next_s = p.elapsed_s + self.every_s
        self._emit({"event": "progress", "state": p.state.value, "line": p.line,
                    "feed_mm_s": round(p.feed_mm_s, 3), "ferror_um": round(p.ferror_um, 1),
                    "fifo_ms": round(p.fifo_ms, 1), "executed_s": round(p.executed_s, 3),
                    "planned_s": p.planned_s, "override_pct": p.override_pct,
                    "position_mm": [round(v, 4) for v in p.position_mm],
                    "work_position_mm": [round(v, 4) for v in p.work_position_mm]})

    def final(self, result: MotionResult) -> None:
        self.final_summary(result_summary(result))

    def final_summary(self, summary: dict[str, Any]) -> None:
        self._emit(summary)

    def close(self) -> None:
        pass


class PlainView:
    """Not a terminal: a status line a second, then a short summary."""

    def __init__(self, lines: Sequence[str], out: TextIO | None = None) -> None:
        self.lines, self.out, self._next_s = lines, out or sys.stdout, 0.0

    def event(self, event: str, **fields: Any) -> None:
        text = output_event_text(fields) if event == "output" else fields_text(fields)
        print(f"cncctl: {event} {text}".rstrip(), file=self.out, flush=True)

    def progress(self, p: MotionProgress) -> None:
        if p.elapsed_s < self._next_s:
            return
        self._next_s = p.elapsed_s + 1.0
        print(status_text(p, self.lines), file=self.out, flush=True)

    def final(self, result: MotionResult) -> None:
        self.final_summary(result_summary(result))

    def final_summary(self, s: dict[str, Any]) -> None:
        print(f"cncctl: {s['event']}{': ' + s['message'] if s['message'] else ''}\n"
              f"  motion {s['motion_time_s']:.3f} s (planned {s['planned_time_s']:.3f} s)"
              f"{_settling_text(s)}, "
              f"contour error max {s['contour_error_um']['max']:.1f} um "
              f"rms {s['contour_error_um']['rms']:.1f} um, following error max "
              f"{s['following_error_um_max']:.0f} um\n"
              f"  underruns {s['underruns']}, late cycles {s['late_cycles']}, "
              f"lowest FIFO {s['min_fifo_ms']:.0f} ms, final position "
              f"{_final_position_text(s)}, pulses {pulses_text(s['pulses'])}"
              f"{_model_text(s)}", file=self.out, flush=True)

    def close(self) -> None:
        if isinstance(self.lines, ProgramLines):
            self.lines.close()


def _model_text(s: dict[str, Any]) -> str:
    """The servo model against the encoder (a daemon of an older version may not send it),
    and the warning where the model no longer holds."""
    r = s.get("model_residual_um") or {}
    if not r.get("samples"):
        return ""
    axes = " ".join(f"{n.upper()} {v['max']:.1f}" for n, v in r.get("axes", {}).items())
    text = (f"\n  model residual max {r['max']:.1f} um rms {r['rms']:.1f} um normal to the path "
            f"(per axis max {axes} um)")
    if s.get("model_warning"):
        text += f"\n  WARNING: {s['model_warning']}"
    return text


def _final_position_text(s: dict[str, Any]) -> str:
    """Where the run ended, or plainly that it is not known (the link was lost: the figures
    are what was commanded, the table may stand millimetres away)."""
    if s.get("position_known", True):
        return axes_text(s["final_position_mm"])
    return (f"UNKNOWN (the drive stopped answering; last commanded "
            f"{axes_text(s['final_position_mm'])}: "
            "home or check the machine before the next job)")


def _line_words(line: int, text: str) -> str:
    """`line 4: G1 X10`; `line -` before the first line is reached."""
    return f"line {line}: {text}" if line > 0 else "line -"


def status_text(p: MotionProgress, lines: Sequence[str]) -> str:
    text = lines_text(lines, p.line)
    planned = f"/{p.planned_s:.2f}" if p.planned_s is not None else ""
    return (f"[{p.state.value}] {p.executed_s:.2f}{planned} s  {_line_words(p.line, text)}  "
            f"feed {p.feed_mm_s:.1f} mm/s ({p.override_pct:g} %)  {position_text(p)}  "
            f"ferror {p.ferror_um:.0f} um  fifo {p.fifo_ms:.0f} ms")


def position_text(p: MotionProgress) -> str:
    machine = " ".join(f"{n}{v:.3f}" for n, v in zip("XYZ", p.position_mm, strict=False))
    if not any(p.work_origin_mm):
        return machine
    work = " ".join(f"{n}{v:.3f}" for n, v in zip("XYZ", p.work_position_mm, strict=False))
    return f"{machine} (work {work})"


class RichView(PlainView):
    """On a terminal: a live progress bar by planned time and a status line under it."""

    def __init__(self, lines: Sequence[str]) -> None:
        super().__init__(lines)
        from rich.console import Group
        from rich.live import Live
        from rich.progress import (
            BarColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )
        self.bar = Progress(TextColumn("{task.fields[state]:>9}"), BarColumn(bar_width=30),
                            TextColumn("{task.completed:.2f}/{task.fields[planned]} s"),
                            TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn())
        self.task = self.bar.add_task("run", total=None, state="start", planned="?")
        self.status = _StatusLine()
        self.live = Live(Group(self.bar, self.status), refresh_per_second=8)
        self.live.start()

    def event(self, event: str, **fields: Any) -> None:
        from rich.markup import escape

        text = output_event_text(fields) if event == "output" else fields_text(fields)
        self.live.console.print(f"[bold]{event}[/] " + escape(text))

    def progress(self, p: MotionProgress) -> None:
        self.bar.update(self.task, completed=p.executed_s, total=p.planned_s,
                        state=p.state.value, planned=f"{p.planned_s:.2f}" if p.planned_s else "?")
        self.status.text = (f"line {p.line}: {lines_text(self.lines, p.line)}\n"
                            f"feed {p.feed_mm_s * 60:.0f} mm/min   override "
                            f"{p.override_pct:g} %   machine {position_text(p)}\n"
                            f"following error {p.ferror_um:.0f} um   card FIFO "
                            f"{p.fifo_ms:.0f} ms   (space: hold/resume, + -: override)")

    def close(self) -> None:
        self.live.stop()
        super().close()


class _StatusLine:
    """A renderable whose text the motion thread replaces; rich redraws it on refresh."""

    text = ""

    def __rich__(self) -> str:
        return self.text


def lines_text(lines: Sequence[str], line: int) -> str:
    return lines[line - 1].strip()[:32] if 0 < line <= len(lines) else ""


def progress_from_event(event: dict[str, Any]) -> MotionProgress:
    """A progress event as the daemon sends it, back into the object the views show."""
    return MotionProgress(state=MotionState(event["state"]), line=int(event["line"]),
                          feed_mm_s=float(event["feed_mm_s"]), ferror_um=float(event["ferror_um"]),
                          fifo_ms=float(event.get("fifo_ms", 0.0)),
                          elapsed_s=float(event.get("elapsed_s", 0.0)),
                          executed_s=float(event["executed_s"]), planned_s=event.get("planned_s"),
                          override_pct=float(event.get("override_pct", 100.0)),
                          position_mm=tuple(float(v) for v in event.get("position_mm", ())),
                          work_origin_mm=tuple(float(v)
                                               for v in event.get("work_origin_mm", ())))
