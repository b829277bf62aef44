"""The SYNC cycle: one frame from the host FIFO per period into RPDO1, then SYNC; TPDO1 back in
as feedback rows; heartbeat, TPDO and EMCY supervision latching CardStatus flags."""

from __future__ import annotations

import collections
import threading
import time
from typing import Any

import can
import numpy as np
from canopen.profiles.p402 import BaseNode402

from drivers.base import CardStatus
from drivers.canopen import cia402 as c
from drivers.canopen.bringup import CAN_ERRORS, label
from drivers.canopen.options import CanopenOptions
from drivers.sim.fifo import FrameFifo

# TPDO1s are matched to SYNCs in order (CAN keeps the order; a late TPDO1 is still matched
# right). A drive owing more than this many (or tpdo_timeout_cycles) is lost communication:
# dropping its oldest SYNC instead paired every later TPDO1 with the wrong target, and a host
# whose reader fell 100 ms behind saw an invented following error of millimetres.
MIN_PENDING = 64
RTT_KEEP = 200_000  # round-trip samples kept for link_stats()


class Link:
    """Shared by the cycle thread, the CAN receive thread (callbacks) and the Drive API."""

    def __init__(self, network: Any, nodes: list[BaseNode402], axes: tuple[str, ...],
                 o: CanopenOptions, period_s: float, pulse_mm: np.ndarray) -> None:
        self.network, self.nodes, self.axes, self.o = network, nodes, axes, o
        self.period_s = period_s
        self.n = len(nodes)
        self.scale = np.array(o.counts_per_mm) * pulse_mm  # counts per pulse
        self.lock = threading.RLock()
        self.fifo = FrameFifo(o.fifo_frames, self.n)
        self.status = CardStatus.OK
        self.messages: list[str] = []
        self.streaming = False
        self.written = 0
        self.discarded = np.zeros(self.n, dtype=np.int64)
        self.cmd = np.zeros(self.n, dtype=np.int64)  # host step counter, pulses
        self.enc = np.zeros(self.n, dtype=np.int64)  # last TPDO position, pulses
        self.base_counts = np.zeros(self.n, dtype=np.int64)
        self.base_pulses = np.zeros(self.n, dtype=np.int64)
        self.statusword = [0] * self.n
        self.counts = [0] * self.n  # last TPDO position actual, drive counts
        self.cycle_no = 0
        self.pending = [collections.deque() for _ in range(self.n)]
        self.rows: dict[int, list[Any]] = {}
        self.sync_s: dict[int, float] = {}
        self.trace: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self.rtt_s: collections.deque[float] = collections.deque(maxlen=RTT_KEEP)
        self.late_tpdos = self.missed_tpdos = self.late_syncs = 0
        self.bad_lines = getattr(network.bus, "bad_lines", 0)
        self.last_hb_s = [time.monotonic()] * self.n
        self.last_tpdo_cycle = [0] * self.n
        self.emcy_seen = [False] * self.n
        self.lost = [False] * self.n
        self.rebooted = [False] * self.n  # a boot-up message since open: homing is lost
        self.supervising = False  # heartbeat/TPDO/state checks, from enable to close
        self.quick_stopped = False
        self.max_pending = max(MIN_PENDING, o.tpdo_timeout_cycles + 2)
        self.hb_every = max(1, round(o.master_heartbeat_ms * 1e-3 / period_s))
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        by_cob = {0x180 + node.id: i for i, node in enumerate(nodes)}
        for cob, i in by_cob.items():
            # First in line: canopen's own PdoMap callback raises on a wrong length and the
            # callbacks after it would not run.
            network.subscribers.setdefault(cob, []).insert(0, self._tpdo_callback(i))
        for i, node in enumerate(nodes):
            node.emcy.add_callback(self._emcy_callback(i))
            node.nmt.add_heartbeat_callback(self._heartbeat_callback(i))
        if network.notifier is not None:
            network.notifier.add_listener(_ReceiveErrors(self, network.notifier))

    # -- conversions ----------------------------------------------------------------------
    def rebase(self, position_counts: list[int]) -> None:
        """Bumpless: the target becomes the drive's actual position, the step counter its
        pulse equivalent."""
        with self.lock:
            self.base_counts = np.array(position_counts, dtype=np.int64)
            self.base_pulses = np.rint(self.base_counts / self.scale).astype(np.int64)
            self.cmd = self.base_pulses.copy()
            self.enc = self.base_pulses.copy()

    def rebase_axes(self, position_counts: dict[int, int]) -> None:
        """rebase() for some axes only (after homing: their drives' new position frame)."""
        with self.lock:
            for i, counts in position_counts.items():
                self.base_counts[i] = counts
                self.base_pulses[i] = int(np.rint(counts / self.scale[i]))
                self.cmd[i] = self.enc[i] = self.base_pulses[i]

    def _targets(self) -> np.ndarray:
        return self.base_counts + np.rint((self.cmd - self.base_pulses) * self.scale).astype(
            np.int64)

    def pulses(self, i: int, counts: int) -> int:
        return int(self.base_pulses[i] + round((counts - self.base_counts[i]) / self.scale[i]))

    # -- latching -------------------------------------------------------------------------
    def latch(self, flag: CardStatus, message: str) -> None:
        with self.lock:
            if message not in self.messages:
                self.messages.append(message)
            self.status |= flag

    # -- the cycle ------------------------------------------------------------------------
    def start(self) -> None:
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="canopen-sync", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        self._thread = None

    def _run(self) -> None:
        next_s = time.monotonic()
        while not self._stop.is_set():
            next_s += self.period_s
            delay_s = next_s - time.monotonic()
            if delay_s > 0:
                time.sleep(delay_s)
            elif -delay_s > self.period_s:  # a whole period late: re-anchor, never burst
                self.late_syncs += 1
                next_s = time.monotonic()
                with self.lock:  # we slept, not the drives: their heartbeat ages exclude it
                    self.last_hb_s = [t - delay_s for t in self.last_hb_s]
            try:
                self.cycle()
            except Exception as exc:  # never die silently: the drives would only see silence
                self.latch(CardStatus.LOST_COMM, f"SYNC cycle failed: {exc!r}")
                return

    def cycle(self) -> None:
        """One period: pop a frame (or hold), RPDO1 to every drive, SYNC, our heartbeat."""
        with self.lock:
            self.cycle_no += 1
            k = self.cycle_no
            if not self.status.halted:
                self._pop(k)
            elif not self.quick_stopped:
                self._quick_stop()
            targets = self._targets()
            payloads = []
            for i, node in enumerate(self.nodes):
                data = bytearray(node.rpdo[1].data)
                c.PDO1.pack_into(data, 0, c.PDO1.unpack_from(data)[0], int(targets[i]))
                payloads.append((0x200 + node.id, bytes(data)))
                if not self.lost[i]:  # a lost drive's late TPDO1s are paired with nothing
                    self.pending[i].append(k)
                if len(self.pending[i]) > self.max_pending:
                    self.missed_tpdos += 1
                    if self.supervising:
                        self.lost[i] = True
                        self.pending[i].clear()
                        self.latch(CardStatus.LOST_COMM, f"lost {label(node, self.axes[i])}: "
                                   f"its TPDO1 is {self.max_pending} SYNC cycles behind")
                    else:  # bring-up, reset: nothing is supervised or paired yet
                        self.pending[i].popleft()
            while self.rows and next(iter(self.rows)) < k - self.max_pending - 1:
                del self.rows[next(iter(self.rows))]
            self.sync_s.pop(k - self.max_pending - 2, None)
            self._check_adapter_lines()
            if self.supervising:
                self._supervise(k)
            self.sync_s[k] = time.monotonic()
        try:
            for cob, data in payloads:
                self.network.send_message(cob, data)
            self.network.send_message(0x80, b"")
            if (k - 1) % self.hb_every == 0:  # from the first cycle on
                self.network.send_message(0x700 + self.o.master_node_id, b"\x05")
        except CAN_ERRORS as exc:
            self.latch(CardStatus.LOST_COMM, f"lost communication with the CAN adapter "
                       f"({self.o.interface} at {self.o.channel}): {exc}")

    def _pop(self, k: int) -> None:
        frames, seq, eos = self.fifo.pop(1)
        if len(frames):
            self.cmd = self.cmd + frames[0]
            self.rows[k] = [int(seq[0]), self.cmd.copy(), np.zeros(self.n, np.int64), 0]
            if eos[0]:
                self.streaming = bool(len(self.fifo))
        elif self.streaming:
            self.latch(CardStatus.UNDERRUN, "drive FIFO underrun: frames ran out mid-program "
                       f"after frame {self.written - 1}; drives quick-stopped")

    def _check_adapter_lines(self) -> None:
        """A line from the adapter that could not be read is a frame lost: from then on a
        TPDO1 may be paired with the wrong SYNC, so it is a fault, never skipped silently."""
        bad = getattr(self.network.bus, "bad_lines", 0)
        if bad != self.bad_lines:
            self.bad_lines = bad
            self.latch(CardStatus.FAULT, f"corrupt frame from the CAN adapter at "
                       f"{self.o.channel} ({bad} so far; last: "
                       f"{getattr(self.network.bus, 'last_bad_line', '')!r})")

    def _quick_stop(self) -> None:
        """Any halt: every enabled drive to QUICK STOP ACTIVE (it holds its position)."""
        self.quick_stopped = True
        for i, node in enumerate(self.nodes):
            if c.state_of(self.statusword[i]) == "OPERATION ENABLED":
                node.controlword = c.CW_QUICK_STOP

    def _supervise(self, k: int) -> None:
        now_s = time.monotonic()
        timeout_s = self.o.heartbeat_timeout_ms * 1e-3
        behind = getattr(self.network.bus, "behind", lambda: False)()
        for i, node in enumerate(self.nodes):
            if self.lost[i]:
                continue
            age_s = now_s - self.last_hb_s[i]
            if age_s > timeout_s and not behind:
                self.lost[i] = True
                self.latch(CardStatus.LOST_COMM, f"lost {label(node, self.axes[i])}: no "
                           f"heartbeat for {age_s:.2f} s (time-out {timeout_s:.2f} s)")
            elif k - self.last_tpdo_cycle[i] > self.o.tpdo_timeout_cycles:
                self.lost[i] = True
                self.latch(CardStatus.LOST_COMM, f"lost {label(node, self.axes[i])}: no TPDO1 "
                           f"for {k - self.last_tpdo_cycle[i]} SYNC cycles")

    # -- callbacks (CAN receive thread) ---------------------------------------------------
    def _tpdo_callback(self, i: int) -> Any:
        def on_tpdo(can_id: int, data: bytes, timestamp: float) -> None:
            now_s = time.monotonic()
            if len(data) != c.PDO1.size:
                self.latch(CardStatus.BAD_FRAME, f"{label(self.nodes[i], self.axes[i])}: "
                           f"TPDO1 has {len(data)} bytes, expected {c.PDO1.size}")
                return
            sw, counts = c.PDO1.unpack_from(data)
            with self.lock:
                self._on_tpdo(i, sw, counts, now_s)
        return on_tpdo

    def _on_tpdo(self, i: int, sw: int, counts: int, now_s: float) -> None:
        self.statusword[i], self.counts[i] = sw, counts
        self.enc[i] = self.pulses(i, counts)
        self.last_tpdo_cycle[i] = self.cycle_no
        if self.pending[i]:
            k = self.pending[i].popleft()
            sent_s = self.sync_s.get(k)
            if sent_s is not None:
                self.rtt_s.append(now_s - sent_s)
                self.late_tpdos += now_s - sent_s > self.period_s
            row = self.rows.get(k)
            if row is not None:
                row[2][i] = self.enc[i]
                row[3] += 1
                if row[3] == self.n:
                    del self.rows[k]
                    self.trace.append((np.array([row[0]]), row[1][None, :],
                                       row[2][None, :]))
        state = c.state_of(sw)
        if not self.supervising or self.status.halted and self.quick_stopped:
            return
        name = label(self.nodes[i], self.axes[i])
        if state == "FAULT" and not self.emcy_seen[i]:
            self.latch(CardStatus.FAULT, f"{name} in FAULT (statusword 0x{sw:04X})")
        elif state not in ("OPERATION ENABLED", "FAULT"):
            self.latch(CardStatus.FAULT, f"{name} left OPERATION ENABLED (now {state})")

    def _emcy_callback(self, i: int) -> Any:
        def on_emcy(err: Any) -> None:
            if err.code == 0:  # error reset
                return
            self.emcy_seen[i] = True
            flag = CardStatus.FOLLOWING_ERROR if err.code == c.EMCY_FOLLOWING_ERROR \
                else CardStatus.FAULT
            self.latch(flag, f"{label(self.nodes[i], self.axes[i])} EMCY {c.emcy_text(err.code)}")
        return on_emcy

    def _heartbeat_callback(self, i: int) -> Any:
        def on_heartbeat(state: int) -> None:
            self.last_hb_s[i] = time.monotonic()
            if state == 0:
                self.rebooted[i] = True
            if state == 0 and self.supervising:
                self.latch(CardStatus.FAULT, f"{label(self.nodes[i], self.axes[i])} rebooted "
                           "(boot-up message)")
        return on_heartbeat

    # -- Drive API support ----------------------------------------------------------------
    def take_trace(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        with self.lock:
            trace, self.trace = self.trace, []
        if not trace:
            return None
        seq, cmd, enc = (np.concatenate(parts) for parts in zip(*trace, strict=True))
        return seq, cmd, enc

    def stats(self) -> dict[str, float | int]:
        with self.lock:
            rtt = np.array(self.rtt_s) * 1e3
            out: dict[str, float | int] = {
                "cycles": self.cycle_no, "tpdos": len(rtt), "late_tpdos": self.late_tpdos,
                "missed_tpdos": self.missed_tpdos, "late_syncs": self.late_syncs}
        if len(rtt):
            out |= {"rtt_p50_ms": float(np.percentile(rtt, 50)),
                    "rtt_p99_ms": float(np.percentile(rtt, 99)), "rtt_max_ms": float(rtt.max())}
        return out


class _ReceiveErrors(can.Listener):
    """The CAN receive thread died (adapter unplugged, peer gone): latch LOST_COMM and stop
    that thread (python-can would otherwise retry a dead device in a busy loop)."""

    def __init__(self, link: Link, notifier: can.Notifier) -> None:
        self.link, self.notifier = link, notifier

    def on_message_received(self, msg: can.Message) -> None:
        return None

    def on_error(self, exc: Exception) -> None:
        self.link.latch(CardStatus.LOST_COMM, f"lost communication with the CAN adapter "
                        f"({self.link.o.interface} at {self.link.o.channel}): {exc}")
        self.notifier._stopped = True  # python-can 4.x: ends its receive loop
