"""cncd's `identify`: the excitation of `cncctl identify` run on the daemon's drive, one axis
after the other, in a thread at the motion thread's scheduling; the fit after it at ordinary
scheduling; its outcome pushed to the client that follows it and kept for `status`."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

from controller.config import MachineConfig, load_config
from controller.errors import CncError, ConfigError
from controller.motion.realtime import realtime_threads
from controller.operator.daemon.job import Emit
from controller.operator.daemon.log import ERR, NOTICE, EventLog
from controller.operator.daemon.protocol import ProtocolError
from controller.operator.identify.loop import AxisRecord, StopRequest, excite_axis
from controller.operator.identify.plan import AxisPlan, PlanRefused, choose_axes, plan_axes
from controller.operator.identify.result import fit_records
from drivers.base import Drive


class IdentifyHost(Protocol):
    """What identify needs of the daemon's Machine (machine.py imports this module)."""

    config: MachineConfig
    drive: Drive
    log: EventLog
    identify_run: IdentifyRun | None

    @property
    def lock(self) -> threading.RLock: ...

    def require_idle(self) -> None: ...

    def require_position(self, what: str) -> None: ...

    def start_identifying(self, run: IdentifyRun) -> None: ...

    def beat(self) -> None: ...

    def end_identify(self, run: IdentifyRun, fault: str | None,
                     outcome: dict[str, Any]) -> None: ...


@dataclass(eq=False)
class IdentifyRun:
    """One identify: its plans, its stop request, whether an axis may still move."""

    plans: list[AxisPlan]
    emit: Emit
    stop: StopRequest = field(default_factory=StopRequest)
    moving: bool = False  # from its start to its last frame clocked (an e-stop otherwise
    # disables the drives at once; while moving, after the fade-out)
    done: threading.Event = field(default_factory=threading.Event)

    def request_stop(self, reason: str) -> None:
        """Abort or e-stop: the axis moving fades out along its excitation, back to rest at
        its start point (identify/loop.py), and no further axis moves."""
        self.stop.request_abort(reason)


def serve(host: IdentifyHost, fields: dict[str, Any], request_id: Any, emit: Emit) -> None:
    """The `identify` request, answered from a thread of its own (designing each axis's
    excitation takes some 40 ms an axis, which the socket loop must not wait for)."""
    threading.Thread(target=_serve, args=(host, fields, request_id, emit),
                     name="identify", daemon=True).start()


def _serve(host: IdentifyHost, fields: dict[str, Any], request_id: Any, emit: Emit) -> None:
    run: IdentifyRun | None = None
    try:
        with host.lock:
            host.require_idle()
            host.require_position("identify")
            if not fields.get("plan_only", False):
                run = IdentifyRun([], emit if fields.get("follow", True) else _nobody)
                host.identify_run = run  # claimed: no job, jog or homing starts meanwhile
        plans = _plans(host, fields)
        if run is None:
            emit({"id": request_id, "ok": True, "windows": [p.as_dict() for p in plans]})
            return
        run.plans = plans
        with host.lock:
            host.start_identifying(run)
    except ProtocolError as exc:
        _release(host, run)
        emit({"id": request_id, "ok": False, "error": exc.code, "message": exc.message})
        return
    except CncError as exc:  # the drive could not be read: nothing moved
        _release(host, run)
        emit({"id": request_id, "ok": False, "error": "drive",
              "message": f"the drive did not answer: {exc}"})
        return
    except Exception as exc:  # noqa: BLE001 - a request never takes the daemon down
        _release(host, run)
        host.log.log(ERR, f"identify: internal error: {type(exc).__name__}: {str(exc)[:200]}")
        emit({"id": request_id, "ok": False, "error": "internal",
              "message": "internal error: see cncctl log"})
        return
    emit({"id": request_id, "ok": True, "state": "IDENTIFYING",
          "windows": [p.as_dict() for p in plans]})
    host.log.log(NOTICE, "identify: " + "; ".join(p.window_text() for p in plans))
    _identify(host, run)


def _nobody(event: dict[str, Any]) -> None:
    """The events of an identify no client follows."""


def _release(host: IdentifyHost, run: IdentifyRun | None) -> None:
    if run is None:
        return
    with host.lock:
        if host.identify_run is run:
            host.identify_run = None
    run.done.set()


def _plans(host: IdentifyHost, fields: dict[str, Any]) -> list[AxisPlan]:
    """The excitations asked for, from where the axes stand; ProtocolError why not."""
    config, drive = host.config, host.drive
    try:
        axes = choose_axes(config, list(fields.get("axes", [])))
    except ConfigError as exc:
        raise ProtocolError("bad-field", exc.message) from None
    if drive.status().halted:
        raise ProtocolError("fault", f"the drive is halted ({drive.fault_message()}): reset "
                                     "first")
    homed = drive.homed()
    unhomed = [config.axes[i].name.upper() for i in axes
               if config.axes[i].homing is not None and not homed[i]]
    if unhomed and not config.allow_unhomed:
        raise ProtocolError("not-homed", f"not homed: {', '.join(unhomed)} (`cncctl home`; "
                                         "the config's allow_unhomed permits it unhomed)")
    cmd, _ = drive.position_counts()
    try:
        plans = plan_axes(config, [int(c) for c in cmd], axes,
                          float(fields.get("window_mm", 10.0)),
                          float(fields.get("duration_s", 4.0)))
    except PlanRefused as exc:
        raise ProtocolError("no-room", str(exc)) from None
    shown = fields.get("from_mm")
    if shown is not None:
        for p in plans:
            if p.name not in shown or \
                    abs(float(shown[p.name]) - p.here_mm) > config.axes[p.index].pulse_mm:
                raise ProtocolError("moved", f"{p.name.upper()} stands at {p.here_mm:.3f} mm, "
                                             "not where the window shown started: ask again")
    return plans


def _identify(host: IdentifyHost, run: IdentifyRun) -> None:
    """Excite each axis (the others hold), then fit; the machine's state and the client told
    how it ended."""
    records: list[AxisRecord] = []
    fault: str | None = None
    outcome: dict[str, Any] = {}
    try:
        with realtime_threads():  # the loop at the motion thread's scheduling
            for plan in run.plans:
                if run.stop.reason is not None:
                    break
                run.emit({"event": "axis", "axis": plan.name,
                          "message": f"exciting {plan.name.upper()}"})
                rec = excite_axis(host.drive, host.config, plan.index, plan.excitation,
                                  run.stop, virtual_time=False, beat=host.beat)
                records.append(rec)
                if rec.fault is not None or rec.stopped is not None:
                    break
    except CncError as exc:
        fault = f"identify: {exc}"
    except Exception as exc:  # noqa: BLE001 - the machine must leave IDENTIFYING whatever
        fault = f"identify failed: {type(exc).__name__}: {exc}"
    with host.lock:
        run.moving = False  # an e-stop from now on disables the drives at once
    last = records[-1] if records else None
    try:
        if fault is None and last is not None and last.fault is not None:
            fault = f"{last.fault}; {last.axis.upper()} stopped, nothing identified"
        if fault is not None:
            outcome = {"event": "fault", "message": fault}
        elif run.stop.reason is not None:
            where = f"{last.axis.upper()} brought back to rest at its start, " if last else ""
            outcome = {"event": "aborted",
                       "message": f"{run.stop.reason}: {where}nothing identified"}
        else:
            outcome = _fitted(host, records)
    except Exception as exc:  # noqa: BLE001 - the fit's bug: logged, the machine goes on
        outcome = {"event": "refused", "message": f"the fit failed: {type(exc).__name__}: "
                                                  f"{str(exc)[:200]}"}
    try:
        host.end_identify(run, fault, outcome)
        run.emit(outcome)
    finally:
        run.done.set()  # after the event is posted: a stopping daemon delivers it first


def _fitted(host: IdentifyHost, records: list[AxisRecord]) -> dict[str, Any]:
    """The fit of every record: `done` with the report and what a client needs to write the
    config (the daemon's config file as it reads now, the parameters), or `refused`."""
    result = fit_records(host.config, records)
    body = result.as_dict()
    if result.problem is not None:
        return {"event": "refused", "message": f"{result.problem}; nothing written", **body}
    if result.refused:
        return {"event": "refused", **body,
                "message": f"the identified loop of "
                           f"{', '.join(n.upper() for n in result.refused)} is refused: "
                           "nothing written"}
    config_text, note = _config_text(host.config)
    if note is not None:
        host.log.log(ERR, f"identify: {note}")
    return {"event": "done", **body, "config_name": host.config.name,
            "config_path": host.config.path, "config_yaml": config_text, "config_note": note}


def _config_text(config: MachineConfig) -> tuple[str | None, str | None]:
    """The config file's text, if it still says what the daemon runs with (drive options
    aside: those of cncd's command line are not the file's); else None and why."""
    try:
        with open(config.path, encoding="utf-8") as fh:
            text = fh.read()
        same = replace(load_config(config.path), drive=config.drive) == config
    except (OSError, CncError) as exc:
        return None, f"the config file {config.path} cannot be read now: {exc}"
    if not same:
        return None, (f"the config file {config.path} changed since cncd started: restart "
                      "cncd to identify with it")
    return text, None
