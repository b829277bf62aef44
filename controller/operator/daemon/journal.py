"""The job journal: what the last job was and how far it got, kept in the state directory so
that it survives a restart (LinuxCNC's POSITION_FILE stance: shown, never acted on)."""

from __future__ import annotations

import json
import time
from typing import Any

from controller.operator.daemon.state_dir import StateDir, StateFileError

JOURNAL_NAME = "journal.json"
IDENTIFY_KEY = "identify"  # the last `cncctl identify`, kept beside the last job


class Journal:
    """One small JSON file in the state directory, replaced atomically at each update. One
    that cannot be read (a link, not a regular file, not a JSON object) is kept aside under a
    new name and reported in `problem`, never silently replaced."""

    def __init__(self, state: StateDir) -> None:
        self.state = state
        self.problem: str | None = None
        self.entry: dict[str, Any] = self._read()

    def _read(self) -> dict[str, Any]:
        try:
            raw = self.state.read(JOURNAL_NAME)
            if raw is None:
                return {}
            data = json.loads(raw.decode("utf-8"))
            if not isinstance(data, dict):
                raise ValueError("not a JSON object")
            return data
        except (StateFileError, ValueError) as exc:
            kept = self.state.keep_aside(JOURNAL_NAME)
            self.problem = (f"the job journal {JOURNAL_NAME} could not be read ({exc}); kept "
                            f"as {kept}: the last job before it is not known")
            return {}

    def update(self, **fields: Any) -> None:
        self.entry = {**self.entry, **fields, "updated": round(time.time(), 3)}
        try:
            self.state.write_atomic(JOURNAL_NAME, json.dumps(self.entry, indent=1).encode())
        except OSError:
            pass  # a full disk must not stop a running job; the journal is advisory

    def start(self, name: str, sha256: str, lines: int) -> None:
        identify = self.entry.get(IDENTIFY_KEY)
        self.entry = {} if identify is None else {IDENTIFY_KEY: identify}
        self.update(program=name, program_sha256=sha256, program_lines=lines, state="RUNNING",
                    last_line=0, position_mm=None, fault=None, started=round(time.time(), 3))

    def identify(self, outcome: dict[str, Any]) -> None:
        """How the last identify went (`started` while it moves), kept across jobs."""
        self.update(**{IDENTIFY_KEY: {**outcome, "at": round(time.time(), 3)}})

    def after_restart(self) -> dict[str, Any]:
        """The journal as found at start-up; a job still RUNNING there was interrupted, and so
        was an identify still `started`."""
        if self.entry.get("state") in ("RUNNING", "CHECKING"):
            self.update(state="INTERRUPTED",
                        fault=self.entry.get("fault") or "daemon stopped during the job")
        identify = self.entry.get(IDENTIFY_KEY)
        if isinstance(identify, dict) and identify.get("event") == "started":
            self.identify({"event": "interrupted",
                           "message": "daemon stopped during identify: nothing identified"})
        return dict(self.entry)
