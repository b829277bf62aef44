"""The daemon's tool table (LinuxCNC's tool.tbl format), kept in the state directory across
restarts like the work offsets: read at start-up, changed by `cncctl tool` between jobs, put in
force for every job (T words checked against it, G43 lengths read from it)."""

from __future__ import annotations

import threading
from dataclasses import replace
from typing import Any

from controller.config import MachineConfig
from controller.operator.daemon.log import NOTICE, EventLog
from controller.operator.daemon.protocol import ProtocolError
from controller.operator.daemon.state_dir import StateDir, StateFileError
from controller.tools import Tool, ToolTable, ToolTableError, check_tool, parse_tool_table

TOOLS_FILE = "tool.tbl"


class ToolStore:
    """The table in force and its file; written under the machine's lock."""

    def __init__(self, config: MachineConfig, state_files: StateDir, log: EventLog,
                 lock: threading.RLock) -> None:
        self.config, self.state_files, self.log, self._lock = config, state_files, log, lock
        self.table = ToolTable()

    def load(self) -> str | None:
        """The table kept across restarts; the problem, if any. One that cannot be read is kept
        aside under a new name and reported: the table is then empty (every T is refused by
        the check) until tools are set again."""
        try:
            raw = self.state_files.read(TOOLS_FILE)
            self.table = ToolTable() if raw is None else parse_tool_table(
                raw.decode("utf-8"), TOOLS_FILE)
        except (StateFileError, ToolTableError, UnicodeDecodeError) as exc:
            kept = self.state_files.keep_aside(TOOLS_FILE)
            self.table = ToolTable()
            return (f"the tool table {TOOLS_FILE} could not be read ({exc}); kept as {kept}: "
                    "the tool table is empty until tools are set again")
        return None

    def job_config(self, config: MachineConfig) -> MachineConfig:
        """The config a job runs with: this table in force."""
        return replace(config, tools=config.tools.with_table(self.table))

    def change(self, fields: dict[str, Any]) -> dict[str, Any]:
        """`tool` request: list, set (tool, pocket, length_mm, diameter_mm, comment) or delete
        (tool); the caller holds the lock and, for a change, has checked that no job runs."""
        action = fields["action"]
        if action == "set":
            table = self.table.with_tool(_tool(fields, self.table.get(fields["tool"])))
        elif action == "delete":
            try:
                table = self.table.without(fields["tool"])
            except KeyError:
                raise ProtocolError("bad-field", f"T{fields['tool']} is not in the tool "
                                                 "table") from None
        else:
            return self.status()
        self._store(table, f"{action} T{fields['tool']}")
        return self.status()

    def _store(self, table: ToolTable, why: str) -> None:
        with self._lock:
            try:
                self.state_files.write_atomic(TOOLS_FILE, table.text().encode())
            except OSError as exc:
                raise ProtocolError("io", f"cannot write the tool table: "
                                          f"{exc.strerror or exc}") from None
            self.table = table
        self.log.log(NOTICE, f"tool table ({why}): {len(table.tools)} tools")

    def status(self) -> dict[str, Any]:
        return {"tools": self.table.describe()}


def _tool(fields: dict[str, Any], old: Tool | None) -> Tool:
    """The tool a set asks for: fields not given keep their old value (pocket: the tool)."""
    number = fields["tool"]
    base = old or Tool(number, number)
    tool = Tool(number, fields.get("pocket", base.pocket),
                float(fields.get("length_mm", base.length_mm)),
                float(fields.get("diameter_mm", base.diameter_mm)),
                fields.get("comment", base.comment))
    try:
        check_tool(tool)
    except ValueError as exc:
        raise ProtocolError("bad-field", str(exc)) from None
    return tool
