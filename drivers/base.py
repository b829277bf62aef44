"""The drive interface (python-can style): public methods over small private backend hooks."""

from __future__ import annotations

import enum
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from controller.blocks import OutputChange
from controller.config import MachineConfig
from controller.errors import DriveError
from controller.outputs import OutputImage, OutputState
from drivers.errors import HomingError
from drivers.homing import plan_for
from drivers.port_lock import PortLock


class CardStatus(enum.Flag):
    """Latched card flags (hostmot2 style: they stay set until reset())."""

    OK = 0
    UNDERRUN = enum.auto()
    FAULT = enum.auto()
    FOLLOWING_ERROR = enum.auto()
    LOST_COMM = enum.auto()
    BAD_FRAME = enum.auto()

    @property
    def halted(self) -> bool:
        """True when the card stopped clocking frames and needs a reset."""
        return self != CardStatus.OK


@dataclass(frozen=True, eq=False)
class Feedback:
    """Frames clocked since the previous feedback() call, one row per frame.

    seq: stream index of each frame (as counted by write_frames since open);
    commanded_counts: accumulated pulses after the frame (the card's step counter);
    encoder_counts: encoder reading after the frame, quantised to the pulse resolution.
    """

    seq: np.ndarray  # (n,) int64
    commanded_counts: np.ndarray  # (n, n_axes) int64
    encoder_counts: np.ndarray  # (n, n_axes) int64

    def __len__(self) -> int:
        return int(self.seq.shape[0])


class Drive(ABC):
    """Base class of every backend; subclasses implement the `_hooks` only."""

    # The drive.options a backend reads; any other key is an error naming it (None: unchecked).
    OPTIONS: frozenset[str] | None = None

    def __init__(self, config: MachineConfig, **options: Any) -> None:
        unknown = sorted(set(options) - self.OPTIONS) if self.OPTIONS is not None else []
        if unknown:
            raise DriveError(f"{config.drive.backend}: unknown drive option "
                             f"{unknown[0]!r} (known: {', '.join(sorted(self.OPTIONS or ()))})")
        self.config = config
        self.options = options
        self.n_axes = len(config.axes)
        self.pulse_mm = np.array([a.pulse_mm for a in config.axes])
        self._is_open = False
        self._homed_axes: set[int] = set()  # axes homed on this open drive (host side)
        self._homing = False  # a home() is running: write_frames is refused
        self._disabled = False  # disable() powered the axes off: until reset()
        self._port_guard: PortLock | None = None  # held while open (see _lock_key)
        self._outputs = OutputState(config.io)  # the machine outputs, kept across jobs

    # -- public API -----------------------------------------------------------------------
    def open(self) -> None:
        self._homed_axes = set()  # a drive just opened is unhomed until home() succeeds
        self._disabled = False  # and enabled by its bring-up (a reset after a lost link)
        lock = self._port_lock()
        self._open_locked(lock, self._open)
        self._is_open = True

    @property
    def is_open(self) -> bool:
        """Opened and not closed since (a failed open leaves it closed)."""
        return self._is_open

    def _port_lock(self) -> PortLock | None:
        if self._port_guard is None and self._lock_key() is not None:
            self._port_guard = PortLock(str(self._lock_key()))
        return self._port_guard

    def _open_locked(self, lock: PortLock | None, action: Callable[[], None]) -> None:
        """action() with the port locked; the lock goes again if it fails."""
        if lock is not None:
            lock.acquire()
        try:
            action()
        except BaseException:
            if lock is not None:
                lock.release()
            raise

    def write_frames(self, counts: np.ndarray, end_of_stream: bool = False) -> None:
        """Queue (N, n_axes) integer pulse counts, one row per sample; EOS marks program end."""
        frames = np.asarray(counts)
        if frames.ndim != 2 or frames.shape[1] != self.n_axes:
            raise DriveError(f"frames must have shape (N, {self.n_axes}), got {frames.shape}")
        if not np.issubdtype(frames.dtype, np.integer):
            raise DriveError("frames must be integer pulse counts")
        self._require_open()
        if self._homing:
            raise DriveError("frames refused: a homing sequence is running")
        if self._disabled:
            raise DriveError("frames refused: the drives are disabled (e-stop); reset() "
                             "enables them")
        self._send_frames(frames.astype(np.int64), end_of_stream)

    def fifo_level(self) -> int:
        """Frames waiting in the card FIFO."""
        self._require_open()
        return self._fifo_level()

    def fifo_capacity(self) -> int:
        return self._fifo_capacity()

    def recall_frames(self, n: int, keep: int) -> int:
        """Take back the last n frames queued and not yet clocked (a feed hold then starts
        behind `keep` frames instead of the whole FIFO). All or nothing: returns n, or 0 when
        fewer than n + keep are queued, one of them ends the stream, or the backend cannot.
        The sequence numbers taken back are reused."""
        self._require_open()
        return self._recall_frames(n, keep) if n > 0 else 0

    def feedback(self) -> Feedback:
        self._require_open()
        return self._read_feedback()

    def position_counts(self) -> tuple[np.ndarray, np.ndarray]:
        """(commanded step counter, encoder counts) now, per axis."""
        self._require_open()
        return self._read_position()

    def commanded_xyz_mm(self) -> tuple[float, float, float]:
        """Where the step counters say the machine stands, as (x, y, z) in mm (0 for an axis
        the machine lacks): where the next program starts."""
        cmd, _ = self.position_counts()
        xyz = dict.fromkeys("xyz", 0.0)
        for axis, counts in zip(self.config.axes, cmd, strict=True):
            xyz[axis.name] = float(counts) * axis.pulse_mm
        return xyz["x"], xyz["y"], xyz["z"]

    def status(self) -> CardStatus:
        self._require_open()
        return self._read_status()

    def fault_message(self) -> str:
        """Human text naming the latched condition(s); empty when status is OK."""
        return self._fault_message()

    def reset(self) -> None:
        """Clear latched flags and discard queued frames (a rising-edge reset); after
        disable(), enable the axes again. Refused while the e-stop input is tripped."""
        self._require_open()
        if self._estop_input():
            raise DriveError("the e-stop input is tripped: release it, then reset")
        self._reset()
        if self._disabled:
            self._enable()
            self._disabled = False

    def disable(self) -> None:
        """The second half of a category 1 stop, once the axes stand still: power them off
        (CiA 402: quick stop, then disable voltage; the serial card's DISABLE; the sim card
        releases its axes). Queued frames are dropped and new ones refused until reset()."""
        self._require_open()
        self._disable()
        self._disabled = True
        try:
            self.safe_outputs()
        except DriveError as exc:
            raise DriveError(f"disabled, but the outputs were not set safe: {exc}") from exc

    def set_outputs(self, changes: Sequence[OutputChange]) -> list[OutputChange]:
        """Set machine outputs (spindle, coolant, digital, analog; see controller/outputs.py)
        through the config's io map; returns the changes that changed a value."""
        return self._set(lambda state: state.apply(changes), only_changed=True)

    def safe_outputs(self) -> list[OutputChange]:
        """Every output to its safe state (spindle and coolant off, the configured safe values),
        written to the hardware even if the state already was (a backend may skip what it
        last wrote on the same link); the changes it made."""
        return self._set(lambda state: state.to_safe(), only_changed=False)

    def _set(self, change: Callable[[OutputState], list[OutputChange]],
             only_changed: bool) -> list[OutputChange]:
        """Change a copy of the outputs, write it, then keep it: the state a failed write
        leaves is still what the hardware was last told."""
        self._require_open()
        state = OutputState(self._outputs.io, **self._outputs.as_dict())
        changed = change(state)
        if changed or not only_changed:
            self._write_outputs(state.image())
            self._outputs = state
        return changed

    def outputs(self) -> dict[str, Any]:
        """The machine outputs as last set (for `status`)."""
        return self._outputs.as_dict()

    def limit_input(self) -> str | None:
        """The hard limit switch that is tripped, named ("X+ limit switch"), or None."""
        return self._limit_input() if self._is_open else None

    @property
    def disabled(self) -> bool:
        """True from disable() until reset() enabled the axes again."""
        return self._disabled

    def estop_input(self) -> bool:
        """The e-stop input (a digital input on the drive or card): True while tripped. A
        drive not open reads False (nothing to stop)."""
        return self._is_open and self._estop_input()

    def probe_input(self) -> bool | None:
        """The probe input (G38): True in contact; None on a drive without one (a probe is
        then refused before any motion)."""
        return self._probe_input() if self._is_open else None

    def home(self, axes: Sequence[int], timeout_s: float = 60.0) -> None:
        """Run the homing sequence of these axes (indices in config.axes order) on the device,
        all of them together; block until done. Afterwards position_counts() reads the machine
        position: each axis stands at its final_mm, and the point found (switch edge, or the
        index mark after it) read home_mm. Only with the FIFO idle (no stream under way).
        Raises HomingError naming the axis and why (no homing configured, switch not found,
        time-out, drive fault during homing); the axes homed are unhomed until it succeeds."""
        self._require_open()
        wanted = self._homing_axes(axes)
        for i in wanted:
            plan_for(self.config, i)  # HomingError when that axis has no homing sequence
        if not wanted:
            return
        if not timeout_s > 0:
            raise HomingError(f"homing time-out must be positive, got {timeout_s!r}")
        names = ", ".join(self.config.axes[i].name.upper() for i in wanted)
        if self._disabled:
            raise HomingError(f"cannot home {names}: the drives are disabled (e-stop); "
                              "reset() first")
        if self._read_status().halted:
            raise HomingError(f"cannot home {names}: the drive is halted "
                              f"({self._fault_message()}); reset() first")
        if self._stream_active():
            raise HomingError(f"cannot home {names}: frames are streaming (homing needs the "
                              "FIFO idle: end the stream and let it run out first)")
        self._homed_axes.difference_update(wanted)
        self.homing_abort_reason = None
        self._homing = True
        try:
            self._home(wanted, timeout_s)
        finally:
            self._homing = False
        self._homed_axes.update(wanted)

    def abort_homing(self, reason: str = "homing aborted") -> None:
        """Stop a homing sequence under way (e-stop, daemon shutdown): it ends in HomingError
        with the axes halted where they are; safe from any thread, a no-op when not homing."""
        self.homing_abort_reason = reason

    homing_abort_reason: str | None = None

    def homing_aborted(self) -> str | None:
        """The reason given to abort_homing() during this homing, if any (backends poll it)."""
        return self.homing_abort_reason if self._homing else None

    def homed(self) -> tuple[bool, ...]:
        """Per axis: True for an axis without a homing sequence (its position is absolute),
        and for one homed by home() on this open drive."""
        self._require_open()
        return tuple(a.homing is None or h for a, h in zip(self.config.axes, self._homed(),
                                                           strict=True))

    def _homing_axes(self, axes: Sequence[int]) -> tuple[int, ...]:
        out: list[int] = []
        for i in axes:
            if isinstance(i, bool) or not isinstance(i, int | np.integer) \
                    or not 0 <= int(i) < self.n_axes:
                raise HomingError(f"no axis {i!r}: axes are indices 0..{self.n_axes - 1} "
                                  f"({', '.join(self.config.axis_names)})")
            if int(i) not in out:
                out.append(int(i))
        return tuple(sorted(out))

    def probe(self) -> None:
        """Check, before any motion, that the backend can be opened and configured as the
        config says (device present, peer answering); nothing is enabled and nothing moves.
        Raises DriveError naming what failed (DriveBusyError: another process has it open,
        which the probe then leaves alone)."""
        lock = self._port_lock()
        self._open_locked(lock, self._probe)
        if lock is not None:
            lock.release()

    def close(self) -> None:
        try:
            if self._is_open:
                self._close()
        finally:
            self._is_open = False
            if self._port_guard is not None:
                self._port_guard.release()

    def __enter__(self) -> Drive:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _require_open(self) -> None:
        if not self._is_open:
            raise DriveError(f"{type(self).__name__}: drive is not open")

    # -- backend hooks --------------------------------------------------------------------
    def _lock_key(self) -> str | None:
        """What this backend opens, locked while it is open (drivers/port_lock.py); None: a
        drive of this process alone (the simulated card)."""
        return None

    @abstractmethod
    def _open(self) -> None:
        """Backend hook."""

    @abstractmethod
    def _send_frames(self, frames: np.ndarray, end_of_stream: bool) -> None:
        """Backend hook."""

    @abstractmethod
    def _fifo_level(self) -> int:
        """Backend hook."""

    @abstractmethod
    def _fifo_capacity(self) -> int:
        """Backend hook."""

    @abstractmethod
    def _read_feedback(self) -> Feedback:
        """Backend hook."""

    @abstractmethod
    def _read_position(self) -> tuple[np.ndarray, np.ndarray]:
        """Backend hook."""

    @abstractmethod
    def _read_status(self) -> CardStatus:
        """Backend hook."""

    def _fault_message(self) -> str:
        return ""

    def _recall_frames(self, n: int, keep: int) -> int:
        """Backend hook; the default cannot recall."""
        return 0

    def _stream_active(self) -> bool:
        """Backend hook: frames queued, or a stream not yet ended (home() is refused)."""
        return self._fifo_level() > 0

    def _home(self, axes: tuple[int, ...], timeout_s: float) -> None:
        """Backend hook: home these axes together (checked: configured, FIFO idle)."""
        raise HomingError(f"the {self.config.drive.backend} backend cannot home")

    def _homed(self) -> tuple[bool, ...]:
        """Backend hook; the default: the axes home() succeeded on since open()."""
        return tuple(i in self._homed_axes for i in range(self.n_axes))

    def _probe(self) -> None:
        """Backend hook; the default opens and closes the drive."""
        self.open()
        self.close()

    @abstractmethod
    def _reset(self) -> None:
        """Backend hook."""

    @abstractmethod
    def _disable(self) -> None:
        """Backend hook: drop queued frames and power the axes off (they stand still)."""

    def _enable(self) -> None:  # noqa: B027 (optional hook: most resets enable by themselves)
        """Backend hook, after _reset() following disable(): power the axes again."""
        return None

    def _estop_input(self) -> bool:
        """Backend hook; the default: a drive without an e-stop input."""
        return False

    def _probe_input(self) -> bool | None:
        """Backend hook; the default: a drive without a probe input."""
        return None

    def _write_outputs(self, image: OutputImage) -> None:  # noqa: B027 (optional hook)
        """Backend hook: drive the digital bits and analog channels (default: the state is
        only kept, as on the sim card)."""
        return None

    def _limit_input(self) -> str | None:
        """Backend hook; the default: a drive without limit switch inputs."""
        return None

    def _close(self) -> None:  # noqa: B027 (optional hook: most backends have nothing to close)
        return None
