"""The model's values kept to what the bridge has seen: each value written when it changes (a
subscriber hears of changes only), and the Notification messages fired as events."""

from __future__ import annotations

import datetime as dt
import os
import time
from pathlib import Path
from typing import Any

from asyncua import Node, ua

from controller import __version__
from controller.opcua_config import OpcuaConfig
from controller.operator.opcua import values
from controller.operator.opcua.model import NOTIFICATION_EVENT_TYPE, Model, StateMachine

STATE_MACHINES = {"Program": "Program", "ItemState": "ItemState",
                  "MachineryMode": "OperationMode"}
TEXTS = {"Manufacturer", "Model"}  # LocalizedText variables
CLOCK_STEP = {"PowerOnDuration": 1000.0, "RunTime": 1.0}  # ms, s: written when this far on


class View:
    def __init__(self, model: Model, config: OpcuaConfig, axes: tuple[str, ...]) -> None:
        self.model, self.config, self.axes = model, config, axes
        self.written: dict[str, Any] = {}
        self.types: dict[str, ua.VariantType] = {}
        self.started_s = started_epoch_s(os.getppid())  # cncd's start: PowerOnDuration
        self.events: Any = None
        self.messages_sent = 0

    async def start(self) -> None:
        """Identification once; the event generator of Notification/Messages."""
        for key, node in self.model.variables.items():
            self.types[key] = await node.read_data_type_as_variant_type()
        c = self.config
        await self.write({"Manufacturer": c.manufacturer, "SerialNumber": c.serial_number,
                          "Model": c.model, "SoftwareRevision": f"phcnc {__version__}",
                          "ProductInstanceUri": f"urn:phcnc:{c.manufacturer}:{c.model}:"
                                                f"{c.serial_number}".replace(" ", "_"),
                          "Name": "Channel1", "NumberInList": 0})
        etype = self.model.server.get_node(ua.NodeId(NOTIFICATION_EVENT_TYPE,
                                                     self.model.ns["MT"]))
        assert self.model.messages is not None
        self.events = await self.model.server.get_event_generator(
            etype, emitting_node=self.model.messages)
        # asyncua reads the imported property's data type as Null and would send Identifier
        # as an empty variant: it is a String (OPC 40501-1, NotificationEventType).
        self.events.event.data_types["Identifier"] = ua.VariantType.String

    async def update(self, seen: values.Seen) -> None:
        now_s = time.time()
        out = values.monitoring_values(seen, self.axes)
        out.update(values.program_values(seen, now_s))
        out["PowerOnDuration"] = (now_s - self.started_s) * 1000.0  # Duration: ms
        # Clocks: to the second. Written at every report they were most of the notifications
        # (and of the server's CPU) with nothing new to say.
        for key in ("PowerOnDuration", "RunTime") if seen.program_job() else (
                "PowerOnDuration",):
            if key in out and self.written.get(key) is not None and \
                    abs(out[key] - self.written[key]) < CLOCK_STEP[key]:
                del out[key]
        await self.write(out)

    async def write(self, new: dict[str, Any]) -> None:
        for key, value in new.items():
            if key in STATE_MACHINES:
                await self._state(key, value)
            elif key in self.model.variables and self.written.get(key, ...) != value:
                await self._write(self.model.variables[key], key, value)

    async def _write(self, node: Node, key: str, value: Any) -> None:
        self.written[key] = value
        vtype = self.types.get(key, ua.VariantType.Variant)
        if key in TEXTS:
            value = ua.LocalizedText(value)
        elif vtype is ua.VariantType.DateTime:
            value = None if value is None else dt.datetime.fromtimestamp(value, dt.UTC)
        data = ua.DataValue(ua.Variant(value, vtype), SourceTimestamp=dt.datetime.now(dt.UTC))
        await node.write_value(data)
        if key in self.model.also:
            await self.model.also[key].write_value(data)

    async def _state(self, key: str, name: str) -> None:
        if self.written.get(key) == name:
            return
        self.written[key] = name
        which = STATE_MACHINES[key]
        for machine in (self.model.machines[which], self.model.twins.get(which)):
            if machine is not None:
                await _enter(machine, name)

    async def message(self, identifier: str, severity: int, text: str) -> None:
        """A Notification message (NotificationEventType) from Notification/Messages."""
        event = self.events.event
        event.Identifier = identifier
        event.Severity = severity
        event.Message = ua.LocalizedText(text[:1000])
        event.SourceName = self.config.machine_name
        event.SourceNode = self.model.machine.nodeid
        await self.events.trigger(time_attr=dt.datetime.now(dt.UTC), message=text[:1000])
        self.messages_sent += 1


async def _enter(machine: StateMachine, name: str) -> None:
    """A state machine's CurrentState, its Id and Number, set to the state called name."""
    state_id, number = machine.states[name]
    await machine.current.write_value(ua.Variant(ua.LocalizedText(name),
                                                 ua.VariantType.LocalizedText))
    await machine.current_id.write_value(ua.Variant(state_id, ua.VariantType.NodeId))
    if machine.current_number is not None:
        await machine.current_number.write_value(ua.Variant(number, ua.VariantType.UInt32))


def started_epoch_s(pid: int) -> float:
    """When a process started (epoch s), from /proc: the server restarted by cncd still counts
    cncd's power-on time. Now, where /proc cannot say."""
    try:
        ticks = int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[19])
        boot_s = next(int(line.split()[1]) for line in Path("/proc/stat").read_text()
                      .splitlines() if line.startswith("btime "))
    except (OSError, ValueError, IndexError, StopIteration):
        return time.time()
    return boot_s + ticks / os.sysconf("SC_CLK_TCK")
