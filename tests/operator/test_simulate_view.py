"""`cncctl simulate`'s progress bar: on a terminal (a real pseudo-terminal), never in a pipe."""

from __future__ import annotations

import json
import os
import pty
import subprocess
import sys
from pathlib import Path

import pytest

CNCCTL = [sys.executable, "-m", "controller.operator.cli"]
# 60 lines of 1 mm: planned in a few windows, its sample blocks end on different lines
ZIGZAG = "G21 G90 G64 F600\n" + "".join(f"G1 X{i + 1} Y{(i % 2) * 0.5}\n" for i in range(60)) \
    + "M2\n"


def _drain(fd: int) -> bytes:
    out = b""
    while True:
        try:
            data = os.read(fd, 65536)
        except OSError:  # EIO: the child closed the terminal
            return out
        if not data:
            return out
        out += data


@pytest.mark.parametrize("json_out", [False, True])
def test_a_terminal_sees_the_line_reached_and_stdout_stays_clean(tmp_path: Path,
                                                                 json_out: bool) -> None:
    program = tmp_path / "zigzag.nc"
    program.write_text(ZIGZAG)
    main, sub = pty.openpty()
    words = ["simulate", str(program)] + (["--json"] if json_out else [])
    proc = subprocess.Popen([*CNCCTL, *words], stdout=subprocess.PIPE, stderr=sub,
                            stdin=subprocess.DEVNULL, close_fds=True)
    os.close(sub)
    try:
        shown = _drain(main)
        out, _ = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        os.close(main)
    assert proc.returncode == 0
    text = shown.decode("utf-8", "replace")
    assert "ph-lookahead" in text and "/62" in text  # 62 lines: the task's total
    assert "G1 X" in text  # the text of the line reached
    assert text.rstrip().endswith("\x1b[2K")  # transient: the bar is cleared at the end
    if json_out:
        assert json.loads(out)["contour_limit_met"] is True
    else:
        assert out.decode().startswith(str(program))


def test_a_pipe_gets_no_bar(tmp_path: Path) -> None:
    program = tmp_path / "zigzag.nc"
    program.write_text(ZIGZAG)
    done = subprocess.run([*CNCCTL, "simulate", str(program)], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0
    assert done.stderr == ""
