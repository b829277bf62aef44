"""Mach3's probing words, read where their meaning is certain: G31, #2000-#2002, M40/M41.

Mach3's G31 is the straight probe that LinuxCNC writes G38.2 (both come from NIST's RS274/NGC
straight probe): it is read as G38.2, and the point where the probe stopped goes to Mach3's
#2000-#2002 (X Y Z, program coordinates) as well as to LinuxCNC's #5061-#5063. Mach3's M40 and
M41 open and close its probe log; Fanuc and Haas read them as gear ranges, so they are read as
the probe log, which writes nothing here, only in a program that probes with G31 (else they are
refused, as LinuxCNC refuses both). Each is accepted with a warning naming the rule.
"""

from __future__ import annotations

import re
from collections.abc import Callable

from controller.interpreter.codes import WordError, m_refusal
from controller.interpreter.params import Parameters

G31_CODE10 = 310
G38_2_CODE10 = 382
PROBE_LOG_CODES = (40, 41)
# Mach3's probe result parameter -> LinuxCNC's (#5061-#5063: X Y Z where the probe stopped)
MACH3_PROBE_RESULT = {2000: 5061, 2001: 5062, 2002: 5063}
_G31_RE = re.compile(r"G\s*0*31(?![\d.])", re.ASCII)
_COMMENT_RE = re.compile(r"\([^)]*\)|;.*", re.ASCII)
_LOG = {40: "open the probe log", 41: "close the probe log"}


class Mach3Probing:
    """G31 lines and the M40/M41 probe log of one program."""

    def __init__(self, path: str, warn_word: Callable[[int, str, str], None]) -> None:
        self.path = path
        self.warn_word = warn_word
        self.probe_line = -1  # the last G31 line read
        self._uses_g31: bool | None = None  # whether the program's file has a G31 (read once)

    def g31(self, lineno: int) -> int:
        """G31: returns G38.2's code; the caller runs the line, then `after_line`."""
        self.probe_line = lineno
        self.warn_word(
            lineno,
            "G31",
            "Mach3's straight probe, read as G38.2; the point where "
            "it stops also goes to #2000-#2002 (Mach3's probe "
            "parameters)",
        )
        return G38_2_CODE10

    def after_line(self, lineno: int, params: Parameters) -> None:
        """After a G31 line: Mach3's #2000-#2002 get the result LinuxCNC's #5061-#5063 hold."""
        if lineno != self.probe_line:
            return
        for mach3, linuxcnc in MACH3_PROBE_RESULT.items():
            if params.is_set(linuxcnc):
                params.set(mach3, params.get(linuxcnc))

    def probe_log(self, ms: list[int], lineno: int) -> list[int]:
        """The line's M codes without M40/M41, accepted as Mach3's probe log (or refused)."""
        for code in ms:
            if code not in PROBE_LOG_CODES:
                continue
            if not self.uses_g31():
                raise WordError(
                    f"M{code}",
                    f"{m_refusal(code)}; read as Mach3's probe log "
                    "only in a program that probes with G31",
                )
            self.warn_word(
                lineno,
                f"M{code}",
                f"Mach3's '{_LOG[code]}' (the program probes with G31): no log is written",
            )
        return [code for code in ms if code not in PROBE_LOG_CODES]

    def uses_g31(self) -> bool:
        """Whether a G31 word stands in the program's file (outside comments)."""
        if self._uses_g31 is None:
            self._uses_g31 = _file_has_g31(self.path)
        return self._uses_g31


def _file_has_g31(path: str) -> bool:
    try:
        with open(path, encoding="utf-8-sig", errors="replace") as handle:
            return any(_G31_RE.search(_COMMENT_RE.sub("", line.upper())) for line in handle)
    except OSError:
        return False
