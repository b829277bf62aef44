"""The canopen backend's machine I/O: outputs written by SDO to the io_node drive (0x60FE digital
outputs, 0x2400 analog outputs), limit switches read from the drives' 0x60FD, and the touch
probe (0x60B8 armed, 0x60B9 and 0x60BA/0x60BB read) on every drive."""

from __future__ import annotations

from typing import Any

from controller.errors import DriveError
from controller.outputs import OutputImage
from drivers.canopen import bringup
from drivers.canopen import cia402 as c
from drivers.canopen.options import CanopenOptions
from drivers.io_peer import switch_name

ALL_OUTPUTS_MASK = 0xFFFF  # 0x60FE:2: every output this controller drives is enabled


def write_outputs(nodes: list[Any], axes: tuple[str, ...], o: CanopenOptions,
                  image: OutputImage, last: OutputImage | None) -> None:
    """The image on the io_node drive: what differs from `last` (all of it, mask first, when
    None), by expedited SDOs while the machine stands at the output mark (each a round trip
    of a few ms on a 1 Mbit/s bus, more through a loaded slcan adapter)."""
    i = o.node_ids.index(o.io_node)
    node, axis = nodes[i], axes[i]
    if last is None:
        bringup.sdo_write(node, axis, c.DIGITAL_OUTPUTS, 2, ALL_OUTPUTS_MASK, "output mask")
    if last is None or image.bits != last.bits:
        bringup.sdo_write(node, axis, c.DIGITAL_OUTPUTS, 1, image.bits, "digital outputs")
    for channel, value in enumerate(image.analog):
        if last is None or value != last.analog[channel]:
            bringup.sdo_write(node, axis, c.ANALOG_OUTPUTS, channel + 1,
                              value, f"analog output {channel}")  # type: ignore[arg-type]


def limit_input(link: Any, nodes: list[Any], axes: tuple[str, ...]) -> str | None:
    """The limit switch a drive reports (statusword bit 11 in its TPDO1, then 0x60FD)."""
    if link is None:
        return None
    with link.lock:
        flagged = [i for i, sw in enumerate(link.statusword) if sw & c.SW_INTERNAL_LIMIT]
    if not flagged:
        return None
    i = flagged[0]
    try:
        inputs = bringup.sdo_read(nodes[i], axes[i], c.DIGITAL_INPUTS, None, "digital inputs")
    except DriveError as exc:  # the switch is open all the same: say which drive, and why
        return f"{axes[i].upper()} limit switch (which side unknown: {exc})"
    direction = 1 if inputs & c.DI_POSITIVE_LIMIT else -1
    return switch_name(axes[i], direction)


def at_speed_input(nodes: list[Any], axes: tuple[str, ...], o: CanopenOptions) -> bool:
    """The spindle's at-speed input: bit 16 of the io_node drive's 0x60FD, read by SDO."""
    i = o.node_ids.index(o.io_node)
    inputs = bringup.sdo_read(nodes[i], axes[i], c.DIGITAL_INPUTS, None, "digital inputs")
    return bool(inputs & c.DI_SPINDLE_AT_SPEED)


def arm_touch_probe(nodes: list[Any], axes: tuple[str, ...], toward: bool) -> None:
    """0x60B8 on every drive: probe 1 on, first event, at the positive edge (toward) or the
    negative; writing it clears what a drive had stored."""
    edge = c.TPF_POSITIVE_EDGE if toward else c.TPF_NEGATIVE_EDGE
    for node, axis in zip(nodes, axes, strict=True):
        bringup.sdo_write(node, axis, c.TOUCH_PROBE_FUNCTION, None, c.TPF_ENABLE | edge,
                          "touch probe function")


def touch_probe_latch(nodes: list[Any], axes: tuple[str, ...], toward: bool) -> list[int] | None:
    """Each drive's latched position (counts) at the armed edge, None if one stored none
    (0x60B9); every probe is then switched off (0x60B8 = 0)."""
    stored = c.TPS_POSITIVE_STORED if toward else c.TPS_NEGATIVE_STORED
    index = c.TOUCH_PROBE_POSITIVE if toward else c.TOUCH_PROBE_NEGATIVE
    counts: list[int] | None = []
    for node, axis in zip(nodes, axes, strict=True):
        status = bringup.sdo_read(node, axis, c.TOUCH_PROBE_STATUS, None, "touch probe status")
        if counts is not None and status & stored:
            counts.append(bringup.sdo_read(node, axis, index, None, "touch probe position"))
        else:
            counts = None
        bringup.sdo_write(node, axis, c.TOUCH_PROBE_FUNCTION, None, 0, "touch probe function")
    return counts
