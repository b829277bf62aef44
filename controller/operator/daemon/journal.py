"""The job journal: what the last job was and how far it got, kept in the state directory so
that it survives a restart (LinuxCNC's POSITION_FILE stance: shown, never acted on)."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

JOURNAL_NAME = "journal.json"


class Journal:
    """One small JSON file, replaced atomically (write, fsync, rename) at each update."""

    def __init__(self, state_dir: Path) -> None:
        self.path = state_dir / JOURNAL_NAME
        self.entry: dict[str, Any] = self._read()

    def _read(self) -> dict[str, Any]:
        try:
            data = json.loads(self.path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return {}
        return data if isinstance(data, dict) else {}

    def update(self, **fields: Any) -> None:
        self.entry = {**self.entry, **fields, "updated": round(time.time(), 3)}
        tmp = self.path.with_suffix(".tmp")
        try:
            with open(tmp, "w", encoding="utf-8") as fh:
                json.dump(self.entry, fh, indent=1)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, self.path)
        except OSError:
            pass  # a full disk must not stop a running job; the journal is advisory

    def start(self, name: str, sha256: str, lines: int) -> None:
        self.entry = {}
        self.update(program=name, program_sha256=sha256, program_lines=lines, state="RUNNING",
                    last_line=0, position_mm=None, fault=None, started=round(time.time(), 3))

    def after_restart(self) -> dict[str, Any]:
        """The journal as found at start-up; a job still RUNNING there was interrupted."""
        if self.entry.get("state") in ("RUNNING", "CHECKING"):
            self.update(state="INTERRUPTED",
                        fault=self.entry.get("fault") or "daemon stopped during the job")
        return dict(self.entry)
