"""The e-stop in the motion loop (virtual time): a category 1 stop, faster than an abort's
jerk-limited stop, along the path at Amax, then the drives disabled until reset."""

from __future__ import annotations

import numpy as np
import pytest
from refgen import circle_chunks
from runtime_helpers import assert_smooth
from test_motion import CFG, on_circle, run

from controller.errors import DriveError
from controller.motion.loop import ESTOP_INPUT, ESTOP_KEEP_MS, MotionController
from controller.motion.types import Outcome

V_MM_S = 58.333  # the circle's feed (refgen.circle_chunks)
AMAX = CFG.interpolator.max_accel_mm_s2
T = CFG.sample_period_s


def _stop_after(ask: str) -> tuple[int, object, object, list]:
    """Frames the card executed after the request, the result, the card and the frames."""
    at: list[int] = []

    def inject(card: object, ctrl: MotionController, _: object) -> None:
        at.append(ctrl.figures.executed)
        if ask == "abort":
            ctrl.request_abort()
        elif ask == "estop":
            ctrl.request_estop("e-stop by operator")
        else:
            card.trip_estop_input()  # type: ignore[attr-defined]
    result, card, rec, _ = run(list(circle_chunks()), inject=inject, at_s=0.4)
    executed = rec.commanded()
    return len(executed) - at[0], result, card, executed


@pytest.mark.parametrize("ask", ["estop", "input"])
def test_the_estop_stops_at_amax_on_the_path_then_disables_the_drive(ask: str) -> None:
    frames, result, card, executed = _stop_after(ask)
    assert result.outcome is Outcome.ABORTED  # type: ignore[attr-defined]
    assert result.message == ("e-stop by operator" if ask == "estop" else ESTOP_INPUT)  # type: ignore[attr-defined]
    on_circle(result, tol_mm=0.002)  # type: ignore[arg-type]
    assert_smooth(executed, np.zeros(2), CFG)  # within Amax (and no position jump)
    # At most: the cycle's own 2 frames, those kept in the card, the stop at Amax (24 ms).
    kept = int(np.ceil(ESTOP_KEEP_MS * 1e-3 / T - 1e-9))
    assert frames <= 2 + kept + int(np.ceil(V_MM_S / AMAX / T)) + 3
    assert card.disabled  # type: ignore[attr-defined]
    with pytest.raises(DriveError, match="disabled"):
        card.write_frames(np.zeros((1, 2), dtype=np.int64))  # type: ignore[attr-defined]
    if ask == "input":
        with pytest.raises(DriveError, match="e-stop input is tripped"):
            card.reset()  # type: ignore[attr-defined]
        card.trip_estop_input(False)  # type: ignore[attr-defined]
    card.reset()  # type: ignore[attr-defined]
    assert not card.disabled  # type: ignore[attr-defined]


def test_the_estop_stops_sooner_than_an_abort() -> None:
    abort_frames, abort, _, _ = _stop_after("abort")
    estop_frames, _, card, _ = _stop_after("estop")
    assert abort.outcome is Outcome.ABORTED  # type: ignore[attr-defined]
    # The abort stops behind the card's FIFO with a jerk-limited quintic (15 v / 8 A):
    assert estop_frames < abort_frames - 20


def test_an_estop_during_an_abort_never_goes_past_the_aborts_stop() -> None:
    """Asked just after an abort, or once its stop is in the card: the abort's stop is
    already queued (it fits in the FIFO at once), so the e-stop ends where it ends, never
    past it (an extension after the stream's end would move the table on), and then
    disables the drives."""
    ends = []
    for delay_cycles in (1, 80):
        def inject(card: object, ctrl: MotionController, pacer: object,
                   delay: int = delay_cycles) -> None:
            ctrl.request_abort()
            for _ in range(delay):
                pacer.wait()  # type: ignore[attr-defined]
                ctrl._cycle()
            ctrl.request_estop("e-stop by operator")
        result, card, rec, _ = run(list(circle_chunks()), inject=inject, at_s=0.4)
        assert result.outcome is Outcome.ABORTED
        assert result.message == "aborted by operator; then e-stop by operator"
        on_circle(result, tol_mm=0.002)
        assert_smooth(rec.commanded(), np.zeros(2), CFG)
        assert card.disabled  # type: ignore[attr-defined]
        ends.append(rec.commanded()[-1].tolist())
    _, abort, _, executed = _stop_after("abort")
    assert ends == [executed[-1].tolist()] * 2
