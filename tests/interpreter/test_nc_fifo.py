"""The NC FIFO across a real process: bounded with back-pressure, every block in order, stops."""

from __future__ import annotations

import multiprocessing as mp
import time
from pathlib import Path

import pytest
from nc_helpers import XY_TABLE

from controller.interpreter.fifo import FAILED, drain_fifo, feed_fifo
from controller.interpreter.program import read_program

_CTX = mp.get_context("fork")  # as the runtime starts its producer processes


def _program(tmp_path: Path, n: int) -> str:
    path = tmp_path / "p.nc"
    path.write_text("F600\n" + "".join(f"G1 X{i % 100} Y{i % 7}\n" for i in range(1, n)))
    return str(path)


def _interpreter(path: str, fifo, stop) -> None:
    feed_fifo(read_program(path, XY_TABLE), fifo, stop.is_set)


def _start(path: str, maxsize: int):
    fifo, stop = _CTX.Queue(maxsize=maxsize), _CTX.Event()
    proc = _CTX.Process(target=_interpreter, args=(path, fifo, stop), daemon=True)
    proc.start()
    return proc, fifo, stop


def _wait_full(fifo) -> None:
    deadline = time.monotonic() + 10
    while not fifo.full() and time.monotonic() < deadline:
        time.sleep(0.01)


def test_a_full_fifo_holds_the_interpreter_back(tmp_path: Path) -> None:
    path = _program(tmp_path, 400)
    proc, fifo, stop = _start(path, maxsize=5)
    try:
        _wait_full(fifo)
        time.sleep(0.2)  # the interpreter would run far ahead if nothing held it
        assert proc.is_alive() and fifo.qsize() == 5
        got = list(drain_fifo(fifo, lambda: not proc.is_alive() and fifo.empty()))
        assert got == list(read_program(path, XY_TABLE))  # every block, in order
        proc.join(timeout=5)
        assert proc.exitcode == 0
    finally:
        stop.set()
        proc.join(timeout=5)


def test_a_stop_ends_a_blocked_interpreter_promptly(tmp_path: Path) -> None:
    proc, fifo, stop = _start(_program(tmp_path, 2000), maxsize=2)
    try:
        _wait_full(fifo)
        t0 = time.monotonic()
        stop.set()
        proc.join(timeout=5)
        assert not proc.is_alive() and proc.exitcode == 0
        assert time.monotonic() - t0 < 1.0
    finally:
        if proc.is_alive():
            proc.kill()


def test_drain_raises_on_failed_and_exits_on_stop() -> None:
    fifo = _CTX.Queue()
    fifo.put("block")
    fifo.put(FAILED)
    items = drain_fifo(fifo, lambda: False)
    assert next(items) == "block"
    with pytest.raises(RuntimeError, match="NC interpreter failed"):
        next(items)
    with pytest.raises(SystemExit):
        next(drain_fifo(_CTX.Queue(), lambda: True))


def test_feed_stops_without_putting_the_rest() -> None:
    fifo = _CTX.Queue(maxsize=1)
    assert feed_fifo(["a", "b", "c"], fifo, lambda: fifo.full()) is False
    assert fifo.get(timeout=1) == "a" and fifo.empty()
