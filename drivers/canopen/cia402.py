"""CiA 301/402 numbers shared by the backend and the simulated drive: objects, words, codes."""

from __future__ import annotations

import struct
from pathlib import Path

EDS_PATH = Path(__file__).with_name("cia402_drive.eds")

# -- objects (index) ----------------------------------------------------------------------
DEVICE_TYPE = 0x1000
ERROR_REGISTER = 0x1001
CONSUMER_HEARTBEAT = 0x1016  # sub 1: (producer node id << 16) | time ms
PRODUCER_HEARTBEAT = 0x1017  # ms
IDENTITY = 0x1018
RPDO1_COMM, RPDO1_MAP, TPDO1_COMM, TPDO1_MAP = 0x1400, 0x1600, 0x1800, 0x1A00
ABORT_CONNECTION = 0x6007  # 0 nothing, 1 fault, 2 disable voltage, 3 quick stop
ERROR_CODE = 0x603F
CONTROLWORD, STATUSWORD = 0x6040, 0x6041
MODE, MODE_DISPLAY = 0x6060, 0x6061
POSITION_DEMAND = 0x6062  # the drive's own reference, counts (bumpless hand-over)
POSITION_ACTUAL = 0x6064
FERROR_WINDOW, FERROR_TIMEOUT = 0x6065, 0x6066  # counts, ms
TARGET_POSITION = 0x607A
INTERPOLATION_PERIOD = 0x60C2  # sub 1 mantissa, sub 2 exponent (10^n s)
SUPPORTED_MODES = 0x6502
HOME_OFFSET = 0x607C  # counts: the position the home point reads once homing is attained
HOMING_METHOD = 0x6098
HOMING_SPEEDS = 0x6099  # sub 1: search for the switch, sub 2: search for zero (latch); counts/s
HOMING_ACCEL = 0x609A  # counts/s^2

MODE_CSP = 8
MODE_HOMING = 6
SUPPORTS_CSP = 0x80  # 0x6502 bit 7
SUPPORTS_HOMING = 0x20  # 0x6502 bit 5

# Homing methods (CiA 402-2): (direction, use_index) -> method. 17/18: the negative/positive
# limit switch, the home point where it releases; 1/2: the first index pulse after that.
HOMING_METHODS = {(-1, False): 17, (1, False): 18, (-1, True): 1, (1, True): 2}
DEVICE_PROFILE_402 = 402  # low 16 bits of 0x1000

# The PDO layout the backend relies on (read back at bring-up): (index, subindex, bits).
RPDO1_LAYOUT = ((CONTROLWORD, 0, 16), (TARGET_POSITION, 0, 32))
TPDO1_LAYOUT = ((STATUSWORD, 0, 16), (POSITION_ACTUAL, 0, 32))
PDO1 = struct.Struct("<Hi")  # both PDO1s: a 16-bit word then a 32-bit position

# -- controlword commands -----------------------------------------------------------------
CW_DISABLE_VOLTAGE = 0x00
CW_QUICK_STOP = 0x02
CW_SHUTDOWN = 0x06
CW_SWITCH_ON = 0x07
CW_ENABLE_OPERATION = 0x0F
CW_HOMING_START = 0x10  # homing mode: a rising edge starts the sequence
CW_FAULT_RESET = 0x80
CW_HALT = 0x100

# -- statusword ---------------------------------------------------------------------------
SW_STATES = (  # (mask, value, name), as canopen.profiles.p402.State402.SW_MASK
    (0x4F, 0x00, "NOT READY TO SWITCH ON"),
    (0x4F, 0x40, "SWITCH ON DISABLED"),
    (0x6F, 0x21, "READY TO SWITCH ON"),
    (0x6F, 0x23, "SWITCHED ON"),
    (0x6F, 0x27, "OPERATION ENABLED"),
    (0x4F, 0x08, "FAULT"),
    (0x4F, 0x0F, "FAULT REACTION ACTIVE"),
    (0x6F, 0x07, "QUICK STOP ACTIVE"),
)
STATE_BITS = {name: value for _, value, name in SW_STATES}
SW_VOLTAGE_ENABLED = 0x0010
SW_QUICK_STOP = 0x0020  # set = quick stop NOT active
SW_REMOTE = 0x0200
SW_TARGET_REACHED = 0x0400  # homing: standing still (done, error or not started)
SW_FOLLOWS_COMMAND = 0x1000  # CSP: drive follows the command value
SW_FOLLOWING_ERROR = 0x2000  # CSP: following error
SW_HOMING_ATTAINED = 0x1000  # homing mode: bit 12
SW_HOMING_ERROR = 0x2000  # homing mode: bit 13
# Manufacturer-specific bit 14: the drive's e-stop input is open. Drives map a digital input
# to it (their statusword-bit configuration); it rides in TPDO1, so the host sees it every T.
SW_ESTOP_INPUT = 0x4000


def state_of(statusword: int) -> str:
    for mask, value, name in SW_STATES:
        if statusword & mask == value:
            return name
    return "UNKNOWN"


# -- EMCY codes ---------------------------------------------------------------------------
EMCY_FOLLOWING_ERROR = 0x8611
EMCY_HEARTBEAT = 0x8130
EMCY_OVERCURRENT = 0x2310
EMCY_TEXT = {
    0x2310: "over-current",
    0x3210: "DC link over-voltage",
    0x4310: "drive over-temperature",
    0x5530: "EEPROM error",
    0x7305: "encoder error",
    0x8130: "heartbeat lost (the drive lost the master's heartbeat)",
    0x8611: "following error",
    0xFF00: "manufacturer-specific fault",
}


def emcy_text(code: int) -> str:
    """0x8611 -> '0x8611 following error' (the class of the code when it is not listed)."""
    name = EMCY_TEXT.get(code) or EMCY_TEXT.get(code & 0xFF00) or {
        0x1000: "generic error", 0x2000: "current", 0x3000: "voltage", 0x4000: "temperature",
        0x5000: "device hardware", 0x6000: "device software", 0x7000: "additional modules",
        0x8000: "monitoring", 0x9000: "external error", 0xF000: "additional functions",
    }.get(code & 0xF000, "error")
    return f"0x{code:04X} {name}"


def period_code(period_s: float) -> tuple[int, int]:
    """0x60C2 (mantissa u8, exponent i8) for a period: 0.001 s -> (1, -3), 0.0025 -> (25, -4)."""
    for exponent in range(-3, -7, -1):
        mantissa = period_s / 10.0**exponent
        if abs(mantissa - round(mantissa)) < 1e-6 * mantissa and round(mantissa) <= 255:
            return int(round(mantissa)), exponent
    raise ValueError(f"sample period {period_s} s cannot be written to 0x60C2")

# Machine I/O (docs/canopen.md, "Machine I/O"): digital inputs with the limit switches, the
# digital outputs on the drive the option io_node names, and its analog outputs, which CiA 402
# does not define (drives put them in manufacturer objects; 0x2400 in our EDS).
DIGITAL_INPUTS = 0x60FD  # bit 0: negative limit switch, bit 1: positive limit switch
DI_NEGATIVE_LIMIT, DI_POSITIVE_LIMIT = 0x1, 0x2
DI_SPINDLE_AT_SPEED = 1 << 16  # the first manufacturer-specific input: the spindle at speed
DIGITAL_OUTPUTS = 0x60FE  # sub 1: physical outputs, sub 2: bit mask (outputs enabled)
ANALOG_OUTPUTS = 0x2400  # sub 1-4: REAL32, channels 0-3
SW_INTERNAL_LIMIT = 0x0800  # statusword bit 11: internal limit active (a limit switch)

# Touch probe (CiA 402 60B8h-60BBh), G38 (docs/canopen.md, "Probing"): the function word arms
# probe 1 for its first edge, the drive latches its own position actual at that edge.
TOUCH_PROBE_FUNCTION = 0x60B8
TOUCH_PROBE_STATUS = 0x60B9
TOUCH_PROBE_POSITIVE = 0x60BA  # touch probe 1 positive edge position, counts
TOUCH_PROBE_NEGATIVE = 0x60BB  # touch probe 1 negative edge position, counts
TPF_ENABLE = 0x0001  # bit 0: probe 1 on; bit 1 clear: first event only; bits 2-3 clear: its input
TPF_POSITIVE_EDGE = 0x0010  # bit 4: latch at the positive edge (contact made)
TPF_NEGATIVE_EDGE = 0x0020  # bit 5: latch at the negative edge (contact lost)
TPS_ENABLED = 0x0001  # 60B9 bit 0: probe 1 is on
TPS_POSITIVE_STORED = 0x0002  # bit 1: a positive edge position is stored (60BA)
TPS_NEGATIVE_STORED = 0x0004  # bit 2: a negative edge position is stored (60BB)
# Manufacturer-specific bit 15: the probe input's level (in contact). Mapped as the e-stop's
# bit 14 is, it rides in TPDO1, so the host sees contact every T without an SDO.
SW_PROBE_INPUT = 0x8000
