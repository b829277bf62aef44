"""MDI: a few G-code lines run as a one-line job, with the modal state kept between them as in
LinuxCNC's MDI. The modes the last MDI job left (units, distance mode, feed, path control,
motion mode) become a prefix of the next one; the daemon checks the whole job before motion."""

from __future__ import annotations

import os
import re
import tempfile

from controller.config import MachineConfig
from controller.errors import NcError
from controller.interpreter.line_state import LineState
from controller.interpreter.program import position_at_line

MAX_MDI_LINES = 20
MAX_MDI_CHARS = 256  # per line
PREFIX_LINES = 2
JOB_NAME = "MDI"
_LINE_RE = re.compile(r"^(?P<name>[^:\n]*):(?P<line>\d+):")


class MdiError(ValueError):
    """MDI text that is not sent: empty, too long, or with characters no line may hold."""


def check_text(text: object) -> list[str]:
    """The MDI lines (blank ones dropped); MdiError when there is nothing or too much."""
    if not isinstance(text, str):
        raise MdiError("mdi needs text, one or a few G-code lines")
    lines = [ln.strip() for ln in text.replace("\r\n", "\n").split("\n") if ln.strip()]
    if not lines:
        raise MdiError("nothing to run: the MDI text is empty")
    if len(lines) > MAX_MDI_LINES or any(len(ln) > MAX_MDI_CHARS for ln in lines):
        raise MdiError(f"MDI takes at most {MAX_MDI_LINES} lines of {MAX_MDI_CHARS} "
                       "characters: upload a program instead")
    if any(not ln.isprintable() or ln.startswith("%") for ln in lines):
        raise MdiError("an MDI line holds a character that is not text, or a %")
    return lines


def prefix_of(state: LineState) -> list[str]:
    """Two lines that bring a fresh program to `state`'s modes. Line 1 is read in mm (a
    program starts in G21): path tolerances are written in mm there; line 2 sets the units,
    distance mode and motion mode the next lines read, and the feed in those units (an F
    number means units per minute of the units in force, as in LinuxCNC)."""
    pc = state.path_control
    tolerances = "".join(f" {letter}{value:.6f}" for letter, value in
                         (("P", pc.tolerance_mm), ("Q", pc.naive_cam_tolerance_mm))
                         if value is not None and str(pc.mode) == "G64")
    per_min = state.feed_mm_s * 60.0 / (25.4 if state.inch else 1.0)
    feed = f" F{per_min:.6f}" if state.feed_mm_s > 0 else ""
    motion = f" {state.motion}" if state.motion in ("G0", "G1") else ""
    return [f"G21 {pc.mode}{tolerances}",
            f"{'G20' if state.inch else 'G21'} {state.distance_mode}{motion}{feed}"]


class MdiSession:
    """The modes MDI keeps between jobs (one session for the panel: the machine has one MDI,
    as LinuxCNC's has)."""

    def __init__(self, config: MachineConfig) -> None:
        self.config = config
        self.prefix = ["G21 G64", "G21 G90"]

    def job_text(self, lines: list[str]) -> bytes:
        """The job sent through the control socket's `run`: the prefix, then the lines."""
        return ("\n".join([*self.prefix, *lines]) + "\n").encode()

    def finished(self, lines: list[str]) -> None:
        """The job ran to its end: its modes are the next job's prefix."""
        text = "\n".join([*self.prefix, *lines, "(end of MDI)"]) + "\n"
        fd, path = tempfile.mkstemp(prefix="mdi-", suffix=".nc")
        try:
            with os.fdopen(fd, "w") as handle:
                handle.write(text)
            state = position_at_line(path, self.config, text.count("\n"))
        except NcError:
            return  # the daemon ran it, so this cannot happen; the modes stay as they were
        finally:
            os.unlink(path)
        self.prefix = prefix_of(state)

    def reset(self) -> None:
        self.prefix = ["G21 G64", "G21 G90"]


def user_message(message: str) -> str:
    """A check error of an MDI job names the MDI line (`MDI:1:...`), not the job's line."""
    m = _LINE_RE.match(message)
    if not m:
        return message
    line = int(m.group("line")) - PREFIX_LINES
    return f"MDI:{max(line, 1)}:{message[m.end():]}"
