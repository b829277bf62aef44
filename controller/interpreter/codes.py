"""G and M code tables: modal groups of the supported codes and why the others are refused."""

from __future__ import annotations

# G codes are keyed by ten times their number (G61.1 -> 611) so that lookups are exact integers.
G_GROUP: dict[int, str] = {
    0: "motion", 10: "motion", 20: "motion", 30: "motion", 51: "motion", 52: "motion", 53: "motion",
    62: "motion", 800: "motion", 382: "motion", 383: "motion", 384: "motion", 385: "motion",
    730: "motion", 810: "motion", 820: "motion", 830: "motion", 850: "motion", 890: "motion",
    40: "non-modal", 100: "non-modal", 530: "non-modal",
    280: "non-modal", 281: "non-modal", 300: "non-modal", 301: "non-modal",
    920: "non-modal", 921: "non-modal", 922: "non-modal",
    170: "plane", 180: "plane", 190: "plane",
    900: "distance", 910: "distance",
    901: "arc distance", 911: "arc distance",
    940: "feed mode",
    200: "units", 210: "units",
    400: "cutter compensation",
    430: "tool length", 431: "tool length", 490: "tool length",
    540: "coordinate system", 550: "coordinate system", 560: "coordinate system",
    570: "coordinate system", 580: "coordinate system", 590: "coordinate system",
    610: "path control", 611: "path control", 640: "path control",
    960: "spindle mode", 970: "spindle mode",
    980: "canned return", 990: "canned return",
}

_CANNED = "this canned cycle is not supported (G73 G81 G82 G83 G85 G89 are)"
_FANUC_POLAR = "Fanuc's polar mode (G15/G16) is not supported; use @ (radius) and ^ (angle)"
_G59_X = "coordinate systems G59.1-G59.3 are not supported (G54-G59 only)"
G_UNSUPPORTED: dict[int, str] = {
    50: "cubic splines (G5) are not supported; use G5.2 NURBS",
    70: "lathe diameter mode is not supported", 80: "lathe radius mode is not supported",
    150: _FANUC_POLAR, 160: _FANUC_POLAR,
    171: "the UV planes (G17.1, G18.1, G19.1) are not supported",
    181: "the UV planes (G17.1, G18.1, G19.1) are not supported",
    191: "the UV planes (G17.1, G18.1, G19.1) are not supported",
    330: "spindle-synchronized motion is not supported",
    331: "rigid tapping is not supported",
    410: "cutter radius compensation is not supported",
    411: "cutter radius compensation is not supported",
    420: "cutter radius compensation is not supported",
    421: "cutter radius compensation is not supported",
    432: "additional tool length offsets are not supported",
    520: "G52 local offsets are not supported",
    591: _G59_X, 592: _G59_X, 593: _G59_X,
    740: "left-hand tapping (G74) is not supported", 760: "threading (G76) is not supported",
    840: _CANNED, 860: _CANNED, 870: _CANNED, 880: _CANNED,
    923: "restoring G92 offsets from parameters (G92.3) is not supported; program G92 again",
    930: "inverse-time feed (G93) is not supported; use G94",
    950: "feed per revolution (G95) is not supported; use G94",
}

M_GROUP: dict[int, str] = {
    0: "stopping", 1: "stopping", 2: "stopping", 30: "stopping",
    6: "tool change", 61: "tool change",
    3: "spindle", 4: "spindle", 5: "spindle",
    7: "coolant", 8: "coolant", 9: "coolant",
    48: "override", 49: "override",
    70: "modal state", 71: "modal state", 72: "modal state", 73: "modal state",
    62: "digital output", 63: "digital output", 64: "digital output", 65: "digital output",
    67: "analog output", 68: "analog output",
}

# M codes that posts for other controllers write; refused like every unknown M code (LinuxCNC
# refuses them too), since what they do there may move the machine or need an answer.
M_OTHER: dict[int, str] = {
    25: "Centroid: move Z to its home position",
    40: "Mach3: open a probe log; Fanuc and Haas: a gear range",
    41: "Mach3: close the probe log; Fanuc and Haas: a gear range",
}


def m_refusal(number: float) -> str:
    """Why an M code is refused: unknown here, and what it means elsewhere when it is known."""
    name = f"M{number:g}"
    other = M_OTHER.get(int(number)) if number == int(number) else None
    if other is None:
        return f"{name} is not supported"
    return f"{name} is not supported: an M code of other controllers ({other})"


def g_name(code10: int) -> str:
    """G61.1 for 611, G1 for 10."""
    whole, tenth = divmod(code10, 10)
    return f"G{whole}.{tenth}" if tenth else f"G{whole}"


def g_code10(number: float) -> int | None:
    """Ten times a G number when it has at most one decimal (G61.1), else None."""
    scaled = number * 10.0
    code = round(scaled)
    return code if abs(scaled - code) < 1e-6 and 0 <= code < 10000 else None


class WordError(Exception):
    """Raised by the helpers of the interpreter: the word (letter or "G5.2") at fault, a message.

    The interpreter turns it into an NcError with the file, line and column of that word."""

    def __init__(self, word: str, message: str) -> None:
        super().__init__(message)
        self.word = word
        self.message = message
