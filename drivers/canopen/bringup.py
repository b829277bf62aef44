"""Bring-up by SDO (heartbeats, following-error window, 0x6007, PDO check, CSP) and the probe."""

from __future__ import annotations

import contextlib
import logging
import time
from typing import Any

import can
import canopen
from canopen.profiles.p402 import BaseNode402
from canopen.sdo import SdoAbortedError, SdoCommunicationError

from controller.errors import DriveError
from drivers.canopen import cia402 as c
from drivers.canopen.options import CanopenOptions
from drivers.canopen.slcan_lines import LineSlcanBus

CAN_ERRORS = (can.CanError, OSError, ValueError)
# The libraries log what our DriveErrors already say ("Transfer aborted by client", "An error
# has caused receiving of messages to stop"); with no handler of theirs, Python's last-resort
# handler printed those lines on every cncctl's stderr.
for _name in ("canopen", "can"):
    logging.getLogger(_name).addHandler(logging.NullHandler())
NOTIFIER_CYCLE_S = 0.05  # receive-thread poll (canopen's 1 s made every close take 1 s)


def label(node: BaseNode402, axis: str) -> str:
    return f"{axis.upper()} axis drive (node {node.id})"


def connect(o: CanopenOptions) -> canopen.Network:
    """Open the adapter; DriveError saying which adapter is missing when it cannot be opened."""
    kwargs: dict[str, Any] = {"interface": o.interface, "channel": o.channel,
                              "bitrate": o.bitrate}
    if o.interface == "slcan":
        kwargs["sleep_after_open"] = 0  # the default waits 2 s for an Arduino-style reset
    if o.interface == "virtual":
        kwargs["receive_own_messages"] = False
    network = canopen.Network()
    network.NOTIFIER_CYCLE = NOTIFIER_CYCLE_S
    try:
        if o.interface == "slcan":  # whole lines per read (drivers/canopen/slcan_lines.py)
            kwargs.pop("interface")
            network.bus = LineSlcanBus(**kwargs)
        network.connect(**kwargs)
    except (*CAN_ERRORS, ImportError) as exc:
        raise DriveError(f"no CAN adapter at {o.channel} (interface {o.interface}, "
                         f"{o.bitrate} bit/s): {exc}") from exc
    return network


def add_nodes(network: canopen.Network, o: CanopenOptions) -> list[BaseNode402]:
    nodes = []
    for node_id in o.node_ids:
        node = BaseNode402(node_id, canopen.import_od(str(c.EDS_PATH), node_id))
        network.add_node(node)
        node.sdo.RESPONSE_TIMEOUT = o.sdo_timeout_s
        nodes.append(node)
    return nodes


def _where(index: int, subindex: int | None) -> str:
    return f"0x{index:04X}" + (f":{subindex}" if subindex is not None else "")


def sdo_read(node: BaseNode402, axis: str, index: int, subindex: int | None = None,
             what: str = "") -> int:
    var = node.sdo[index] if subindex is None else node.sdo[index][subindex]
    try:
        return int(var.raw)
    except SdoAbortedError as exc:
        raise DriveError(f"{label(node, axis)}: SDO read of {_where(index, subindex)} {what} "
                         f"aborted by the drive ({exc})") from exc
    except SdoCommunicationError as exc:
        raise DriveError(f"{label(node, axis)} does not answer: no SDO response reading "
                         f"{_where(index, subindex)} {what} ({exc}); is it powered, on this "
                         "bus, at this node id and bitrate?") from exc
    except CAN_ERRORS as exc:
        raise DriveError(f"CAN adapter failed reading {_where(index, subindex)} from "
                         f"{label(node, axis)}: {exc}") from exc


def sdo_write(node: BaseNode402, axis: str, index: int, subindex: int | None, value: int,
              what: str) -> None:
    var = node.sdo[index] if subindex is None else node.sdo[index][subindex]
    try:
        var.raw = value
    except SdoAbortedError as exc:
        raise DriveError(f"{label(node, axis)}: SDO write of {_where(index, subindex)} "
                         f"({what}) = {value} aborted by the drive ({exc})") from exc
    except SdoCommunicationError as exc:
        raise DriveError(f"{label(node, axis)} does not answer: no SDO response writing "
                         f"{_where(index, subindex)} ({what}): {exc}") from exc
    except CAN_ERRORS as exc:
        raise DriveError(f"CAN adapter failed writing {_where(index, subindex)} to "
                         f"{label(node, axis)}: {exc}") from exc


def identify(node: BaseNode402, axis: str) -> dict[str, int]:
    """Device type, identity and mode support; DriveError unless a CiA 402 drive with CSP."""
    device = sdo_read(node, axis, c.DEVICE_TYPE, None, "device type")
    if device & 0xFFFF != c.DEVICE_PROFILE_402:
        raise DriveError(f"{label(node, axis)}: device type 0x{device:08X} (0x1000) is not a "
                         "CiA 402 drive")
    info = {"device_type": device,
            "vendor_id": sdo_read(node, axis, c.IDENTITY, 1, "vendor id"),
            "product_code": sdo_read(node, axis, c.IDENTITY, 2, "product code"),
            "modes": sdo_read(node, axis, c.SUPPORTED_MODES, None, "supported modes")}
    if not info["modes"] & c.SUPPORTS_CSP:
        raise DriveError(f"{label(node, axis)}: does not support cyclic synchronous position "
                         f"mode (0x6502 = 0x{info['modes']:08X})")
    return info


def configure(node: BaseNode402, axis: str, o: CanopenOptions, counts_per_mm: float,
              period_s: float) -> None:
    """PRE-OPERATIONAL writes, PDO layout check, NMT start, CSP read back from 0x6061."""
    node.nmt.state = "PRE-OPERATIONAL"
    identify(node, axis)
    mantissa, exponent = c.period_code(period_s)
    writes = (
        (c.PRODUCER_HEARTBEAT, None, o.drive_heartbeat_ms, "drive heartbeat period, ms"),
        (c.CONSUMER_HEARTBEAT, 1, (o.master_node_id << 16) | o.heartbeat_timeout_ms,
         "heartbeat consumer: our node id and time-out, ms"),
        (c.FERROR_WINDOW, None, int(round(o.ferror_window_mm * counts_per_mm)),
         "following-error window, counts"),
        (c.FERROR_TIMEOUT, None, o.ferror_timeout_ms, "following-error time-out, ms"),
        (c.ABORT_CONNECTION, None, 1, "loss of communication -> fault"),
        (c.INTERPOLATION_PERIOD, 1, mantissa, "interpolation period value"),
        (c.INTERPOLATION_PERIOD, 2, exponent, "interpolation period index"),
    )
    for index, subindex, value, what in writes:
        sdo_write(node, axis, index, subindex, value, what)
    check_pdos(node, axis)
    node.nmt.state = "OPERATIONAL"
    sdo_write(node, axis, c.MODE, None, c.MODE_CSP, "mode of operation: CSP")
    shown = sdo_read(node, axis, c.MODE_DISPLAY, None, "mode of operation display")
    if shown != c.MODE_CSP:
        raise DriveError(f"{label(node, axis)}: did not switch to cyclic synchronous position "
                         f"mode: 0x6061 reads {shown} after writing 8 to 0x6060")


def check_pdos(node: BaseNode402, axis: str) -> None:
    """Read the PDO configuration back (SDO) and compare RPDO1/TPDO1 with our layout."""
    try:
        node.setup_pdos(True)  # reads 0x1400/0x1600/0x1800/0x1A00, subscribes the TPDOs
    except (SdoAbortedError, SdoCommunicationError) as exc:
        raise DriveError(f"{label(node, axis)}: reading the PDO configuration failed: "
                         f"{exc}") from exc
    for name, pdo, cob, layout in (("RPDO1", node.rpdo[1], 0x200 + node.id, c.RPDO1_LAYOUT),
                                   ("TPDO1", node.tpdo[1], 0x180 + node.id, c.TPDO1_LAYOUT)):
        got = tuple((v.index, v.subindex, v.length) for v in pdo.map if v.length)
        problems = []
        if not pdo.enabled:
            problems.append("disabled")
        if pdo.cob_id != cob:
            problems.append(f"COB-ID 0x{pdo.cob_id:X} (expected 0x{cob:X})")
        if pdo.trans_type is None or pdo.trans_type > 240:
            problems.append(f"transmission type {pdo.trans_type} (expected synchronous, 1)")
        if got != layout:
            problems.append("maps " + _layout(got) + " (expected " + _layout(layout) + ")")
        if problems:
            raise DriveError(f"{label(node, axis)}: {name} is not as expected: "
                             + "; ".join(problems))


def _layout(entries: tuple[tuple[int, int, int], ...]) -> str:
    return "[" + ", ".join(f"0x{i:04X}:{s} ({b} bits)" for i, s, b in entries) + "]"


def wait_statusword(node: BaseNode402, axis: str, timeout_s: float = 0.5) -> int:
    try:
        return int(node.check_statusword(timeout_s))
    except RuntimeError as exc:
        raise DriveError(f"{label(node, axis)}: no TPDO1 (statusword) within {timeout_s} s "
                         "of SYNC") from exc


def fault_reset(node: BaseNode402, axis: str, timeout_s: float = 0.5) -> None:
    """Transition 15 on a rising edge of controlword bit 7 (not p402's reset_from_fault)."""
    node.controlword = c.CW_DISABLE_VOLTAGE
    wait_statusword(node, axis)
    wait_statusword(node, axis)
    node.controlword = c.CW_FAULT_RESET
    deadline = time.monotonic() + timeout_s
    while c.state_of(wait_statusword(node, axis)) == "FAULT":
        if time.monotonic() > deadline:
            code = sdo_read(node, axis, c.ERROR_CODE, None, "error code")
            raise DriveError(f"{label(node, axis)} stays in FAULT after a fault reset "
                             f"(0x603F = {c.emcy_text(code)})")
    node.controlword = c.CW_DISABLE_VOLTAGE


def enable(node: BaseNode402, axis: str) -> None:
    """Walk the CiA 402 state machine to OPERATION ENABLED (RPDO1 carried by our SYNC cycle)."""
    if c.state_of(wait_statusword(node, axis)) == "FAULT":
        fault_reset(node, axis)
    try:
        node.state = "OPERATION ENABLED"
    except (RuntimeError, ValueError) as exc:
        raise DriveError(f"{label(node, axis)}: could not be enabled ({exc}; state "
                         f"{c.state_of(node.statusword)})") from exc


def probe(o: CanopenOptions, axes: tuple[str, ...]) -> None:
    """Adapter present, every node answers as a CiA 402 drive with CSP; nothing enabled."""
    network = connect(o)
    try:
        for node, axis in zip(add_nodes(network, o), axes, strict=True):
            identify(node, axis)
    finally:
        # disconnect() re-raises what the receive thread met (a broken adapter): the probe's
        # own answer, or its DriveError, is what counts.
        with contextlib.suppress(Exception):
            network.disconnect()
