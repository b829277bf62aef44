"""`cncctl --help` and every command's help render: the first thing a new user types."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import pytest

from controller.operator.cli import COMMANDS, build_parser
from controller.operator.daemon.main import build_parser as build_daemon_parser


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(actions[0].choices)


def test_the_top_level_help_lists_every_command() -> None:
    text = build_parser().format_help()
    for name, _, help_text in COMMANDS:
        assert name in text
        # argparse %-formats each command's help: a bare % once crashed the whole --help
        assert " ".join(help_text.split()[:3]) in " ".join(text.split())


@pytest.mark.parametrize("name", [name for name, _, _ in COMMANDS])
def test_every_command_help_renders(name: str) -> None:
    sub = _subparsers(build_parser(name))[name]
    text = sub.format_help()
    assert text.startswith(f"usage: cncctl {name}")


def test_the_daemon_help_renders() -> None:
    assert "usage: cncd" in build_daemon_parser().format_help()


@pytest.mark.parametrize("words", [["--help"], ["-h"], ["feed", "--help"]])
def test_help_from_a_real_process_exits_zero(words: list[str]) -> None:
    done = subprocess.run([sys.executable, "-m", "controller.operator.cli", *words],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("usage: cncctl")
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize("words", [
    ["log", "-n", "-5"],  # printed nothing and exited 0
    ["status", "--socket", ""],  # an unset $SOCK: the default socket in silence
    ["run", "nc_programs/arcs.nc", "--socket", ""],  # ... or an embedded run
])
def test_bad_arguments_are_refused_before_anything_happens(
        words: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    from controller.operator.cli import main

    with pytest.raises(SystemExit) as info:
        main(words)
    assert info.value.code == 2
    assert "error: argument" in capsys.readouterr().err


def test_run_through_a_daemon_names_a_missing_program_as_check_does(
        tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    from controller.operator.cli import main

    missing = tmp_path / "none.nc"
    assert main(["run", str(missing), "--socket", str(tmp_path / "d.sock")]) == 2
    assert capsys.readouterr().err.startswith(f"{missing}:0:0: error: cannot open program")


def test_from_line_asks_nothing_when_no_daemon_answers(
        tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    from controller.operator.cli import main

    arcs = str(Path(__file__).resolve().parents[2] / "nc_programs/arcs.nc")
    code = main(["run", arcs, "--from-line", "2", "--socket",
                 str(tmp_path / "d.sock")])
    err = capsys.readouterr().err
    # No daemon: nothing moved, so rejected (2), as docs/operator.md's exit codes say.
    assert code == 2 and "no daemon" in err and "nothing moved" in err
    assert "first moves" not in err


def test_a_lost_position_is_said_plainly_in_the_text_summary(
        capsys: pytest.CaptureFixture[str]) -> None:
    from controller.operator.run.view import PlainView

    summary = {"event": "fault", "message": "serial link lost", "motion_time_s": 1.0,
               "planned_time_s": 2.0, "contour_error_um": {"max": 1.0, "rms": 0.5},
               "following_error_um_max": 3.0, "underruns": 0, "late_cycles": 0,
               "min_fifo_ms": 90.0, "final_position_mm": {"x": 28.337, "y": -43.295},
               "pulses": {}, "position_known": False}
    view = PlainView([])
    view.final_summary(summary)
    out = capsys.readouterr().out
    assert "final position UNKNOWN" in out and "home or check the machine" in out
    view.final_summary(summary | {"position_known": True})
    assert "final position X 28.337 Y -43.295 mm, pulses none" in capsys.readouterr().out
