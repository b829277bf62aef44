"""G38.2-G38.5 in the interpreter (LinuxCNC's straight probe): checks, the ProbeBlock, and
reading on from the probe's result.

LinuxCNC's errors: a probe needs a feed (G94) and at least one axis word; it is one straight
move in the program's frame. A probe of zero length does not run (Probing._zero_length).
After it the position is where the machine stopped, and #5061-#5063 and #5070 hold the
result (controller/probe.py). Without a result (`check`) the probe is taken to go the whole
way: the travel check then covers the farthest it can go.
"""

from __future__ import annotations

from collections.abc import Callable

from controller.blocks import NcBlock, ProbeBlock, Source
from controller.interpreter.codes import WordError, g_name
from controller.interpreter.modal import Modal
from controller.interpreter.moves import Moves
from controller.interpreter.work_offsets import WorkOffsets
from controller.probe import ProbeResult, ProbeResults

PROBE_CODE10 = frozenset((382, 383, 384, 385))


class Probing:
    """The probes of a program; `results` says what those already run found."""

    def __init__(self, modal: Modal, offsets: WorkOffsets, moves: Moves, path: str,
                 out: list[NcBlock], results: ProbeResults | None) -> None:
        self.modal, self.offsets, self.moves, self.path, self.out = modal, offsets, moves, path, out
        self.results = results if results is not None else ProbeResults()
        self.stop_reading = False  # a probe without a result under a barrier: read no further
        self.resume_here = False  # the stretch's output starts after this line's probe

    def probe(self, code10: int, vals: dict[str, float], lineno: int) -> None:
        name = g_name(code10)
        if not {"X", "Y", "Z", "@", "^"} & vals.keys():
            raise WordError(name, f"{name} needs an axis word: the probe's end point")
        if self.modal.feed_mm_s <= 0.0:
            raise WordError(name, f"{name} probe move with no feed rate: program F first")
        self.modal.motion = code10
        start = self.modal.pos
        end = self.moves._end_point(vals)
        if end == start:
            self._read_on(_zero_length(code10, name, lineno, start))
            return
        self.out.append(ProbeBlock(name, start, end, self.modal.feed_mm_s,
                                   Source(self.path, lineno, lineno)))
        self.results.seen[lineno] = name
        result, self.resume_here = self.results.next_result()
        if result is not None and not result.tripped and code10 in (382, 384):
            raise WordError(name, f"{name}: the probe move ended without "
                                  f"{'making' if code10 == 382 else 'losing'} contact")
        if result is None and self.results.barrier:
            self.results.stopped_at = lineno
            self.stop_reading = True
            return
        if result is None:  # check: as if the probe went the whole way and tripped there
            result = ProbeResult(lineno, True, end, end)
        self._read_on(result)

    def _read_on(self, result: ProbeResult) -> None:
        """The program goes on where the probe stopped, with #5061-#5063 and #5070 its."""
        self.modal.pos = result.stop_mm
        origin = self.offsets.origin or (0.0, 0.0, 0.0)
        self.results.parameters.update(result.parameters(origin))

    def set_parameters(self, set_number: Callable[[int, float], None]) -> bool:
        """#5061-#5063 and #5070 for what follows the probe just read; whether a probing
        run's stretch starts after it."""
        for number, value in self.results.parameters.items():
            set_number(number, value)
        return self.resume_here


def _zero_length(code10: int, name: str, lineno: int,
                 here: tuple[float, float, float]) -> ProbeResult:
    """A probe to where it stands (smartprobe.ngc's G38.5 at its safe height): no move can make
    or lose contact, so it does not run. G38.2/G38.4 would fail; G38.3/G38.5 end at once
    without contact (#5070 = 0, #5061-#5063 where the machine stands), as in LinuxCNC."""
    if code10 in (382, 384):
        raise WordError(name, f"{name}: the probe's end point is where it stands (a move of "
                              f"zero length cannot {'make' if code10 == 382 else 'lose'} contact)")
    return ProbeResult(lineno, False, here, here)
