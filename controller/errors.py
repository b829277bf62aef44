"""One exception tree for the whole controller (python-can style)."""

from __future__ import annotations


class CncError(Exception):
    """Base of every error the controller raises on purpose."""


class ConfigError(CncError):
    """A machine configuration file is wrong: names the file and the key."""

    def __init__(self, path: str, key: str, message: str) -> None:
        self.path = path
        self.key = key
        self.message = message
        super().__init__(f"{path}: {key}: {message}")


class NcError(CncError):
    """A G-code program is wrong: names file, line, column and the word at fault."""

    def __init__(self, path: str, line: int, col: int, word: str, message: str) -> None:
        self.path = path
        self.line = line
        self.col = col
        self.word = word
        self.message = message
        super().__init__(self.format())

    def format(self) -> str:
        """The compiler-style one-line form `PROGRAM:LINE:COL: error: MESSAGE`."""
        return f"{self.path}:{self.line}:{self.col}: error: {self.message}"


class PlanningError(CncError):
    """The reference-point generator cannot meet a limit (reported, never silent)."""


class DriveError(CncError):
    """A drive backend fault: drive fault, lost communication, underrun, following error."""


class OffsetsError(CncError):
    """The work-offset file (G54-G59, G92) cannot be read or written: names the file."""

    def __init__(self, path: str, message: str) -> None:
        self.path = path
        self.message = message
        super().__init__(f"{path}: {message}")
