"""The outputs in words: `cncctl status`'s line and a run's output events for a person."""

from __future__ import annotations

from controller.operator.io_text import output_event_text, outputs_text


def test_status_line_names_every_output() -> None:
    assert outputs_text({"spindle": "ccw", "spindle_rpm": 1200.0, "coolant_mist": True,
                         "coolant_flood": True, "digital": [False, True],
                         "analog": [2.5]}) == (
        "spindle ccw 1200 rpm, coolant mist flood, digital P0 off P1 on, analog E0 2.5")
    assert outputs_text({"spindle": "off", "spindle_rpm": 1200.0, "coolant_mist": False,
                         "coolant_flood": False, "digital": [], "analog": []}) == (
        "spindle off, coolant off")


def test_event_text_reads_on_and_off_and_says_safe() -> None:
    assert output_event_text({"t_s": 1.003, "line": 3, "name": "coolant_flood",
                              "value": True}) == "line 3: coolant_flood on (t 1.003 s)"
    assert output_event_text({"t_s": 2.0, "line": 9, "name": "analog_0", "value": 0.0,
                              "safe": True}) == "line 9: analog_0 0 (t 2.0 s, safe state)"
    assert output_event_text({"t_s": 0.5, "line": 2, "name": "spindle",
                              "value": "cw"}) == "line 2: spindle cw (t 0.5 s)"
