"""What the Machine Tools model says for a state of cncd: its status and progress mapped onto
the companion model's values (operation mode, channel state and mode, the program's state
machine), without a server, so the mapping is tested on its own."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

# OPC 40501-1 enumerations (the values of the NodeSet's EnumValues)
OPERATION_MODE = {"Manual": 0, "Automatic": 1, "Setup": 2, "AutoWithManualIntervention": 3,
                  "Service": 4, "Other": 5}
CHANNEL_STATE = {"Active": 0, "Interrupted": 1, "Reset": 2}
CHANNEL_MODE = {"Automatic": 0, "MdaMdi": 1, "JogManual": 2, "JogIncrement": 3,
                "TeachingHandle": 4, "Remote": 5, "Reference": 6, "Other": 7}
MOVING = ("CHECKING", "RUNNING", "HOMING", "IDENTIFYING")
WAITING = ("PAUSED", "HELD")
# The journal's outcome of the last job -> the state ProductionProgramStateMachineType ends in.
ENDED_AS = {"DONE": "Ended", "ABORTED": "Aborted", "FAULT": "Aborted",
            "INTERRUPTED": "Aborted", "RUNNING": "Running"}


@dataclass
class Seen:
    """What the bridge knows of cncd: the last status, updated by the events in between."""

    status: dict[str, Any] = field(default_factory=dict)
    progress: dict[str, Any] | None = None  # the running job's last progress event
    job_started_s: dict[int, float] = field(default_factory=dict)  # job -> epoch its motion began

    def job(self) -> int | None:
        return self.status.get("job")

    def program_job(self) -> bool:
        """A program runs (not a jog, which is a job of its own kind)."""
        return self.job() is not None and not self.status.get("manual_move")


def operation_mode(seen: Seen) -> str:
    state = seen.status.get("state")
    if state == "HOMING":
        return "Setup"
    if state == "IDENTIFYING":
        return "Service"
    if seen.program_job():
        return "Automatic"
    return "Manual"  # idle, e-stop, fault, jogs: the operator's hand


def channel_state(seen: Seen) -> str:
    state = seen.status.get("state")
    if state in WAITING:
        return "Interrupted"
    if state in MOVING:
        return "Active"
    return "Reset"


def channel_mode(seen: Seen) -> str:
    state = seen.status.get("state")
    if state == "HOMING":
        return "Reference"
    if state == "IDENTIFYING":
        return "Other"
    if seen.job() is not None and seen.status.get("manual_move"):
        return "JogManual"
    return "Automatic"


def item_state(seen: Seen) -> str:
    """Machinery's MachineryItemState: out of service while e-stopped or faulted."""
    state = seen.status.get("state")
    if state in ("ESTOP", "FAULT"):
        return "OutOfService"
    if state in MOVING:
        return "Executing"
    if state is None:
        return "NotAvailable"
    return "NotExecuting"


def machinery_mode(seen: Seen) -> str:
    state = seen.status.get("state")
    if state in ("HOMING", "IDENTIFYING") or (seen.job() is not None and not
                                               seen.program_job()):
        return "Setup"
    return "Processing" if seen.program_job() else "None"


def program_values(seen: Seen, now_s: float) -> dict[str, Any]:
    """Production/ActiveProgram: the running program, else the last one (the journal's)."""
    st = seen.status
    if seen.program_job():
        state = st.get("state")
        p_state = ("Initializing" if state == "CHECKING" else
                   "Interrupted" if state in WAITING else "Running")
        started = seen.job_started_s.get(st["job"])
        line = (seen.progress or {}).get("line") or st.get("line") or 0
        return {"ProgramName": st.get("program") or "", "Hash": st.get("program_sha256") or "",
                "JobIdentifier": str(st["job"]), "Line": int(line), "Program": p_state,
                "StartTime": started, "RunTime": now_s - started if started else 0.0}
    last = st.get("last_job") or {}
    if not last.get("program"):
        return {}
    started, updated = last.get("started"), last.get("updated")
    run_s = updated - started if isinstance(started, float | int) and \
        isinstance(updated, float | int) and last.get("state") != "RUNNING" else 0.0
    return {"ProgramName": last["program"], "Hash": last.get("program_sha256") or "",
            "Line": int(last.get("last_line") or 0),
            "Program": ENDED_AS.get(str(last.get("state")), "Aborted"),
            "StartTime": float(started) if isinstance(started, float | int) else None,
            "RunTime": max(0.0, float(run_s))}


def monitoring_values(seen: Seen, axes: tuple[str, ...]) -> dict[str, Any]:
    st, p = seen.status, seen.progress
    out: dict[str, Any] = {
        "OperationMode": OPERATION_MODE[operation_mode(seen)],
        "ChannelState": CHANNEL_STATE[channel_state(seen)],
        "ChannelMode": CHANNEL_MODE[channel_mode(seen)],
        "FeedOverride": float(p["override_pct"] if p else st.get("feed_override_pct", 100.0)),
        "FeedRate": float(p["feed_mm_s"] if p else st.get("feed_mm_s", 0.0)),
        "ItemState": item_state(seen), "MachineryMode": machinery_mode(seen),
    }
    positions = _positions(seen, axes)
    for axis, value in positions.items():
        out[f"Position{axis.upper()}"] = value
    return out


def _positions(seen: Seen, axes: tuple[str, ...]) -> dict[str, float]:
    """The encoder position: the running job's last progress, else the status's."""
    if seen.progress is not None and seen.progress.get("position_mm"):
        return {a: float(v) for a, v in zip(axes, seen.progress["position_mm"], strict=False)}
    pos = seen.status.get("position_mm") or {}
    return {a: float(pos[a]) for a in axes if a in pos}


def message_for(before: dict[str, Any], after: dict[str, Any]) -> tuple[str, int, str] | None:
    """The Notification message a state change raises: (identifier, severity, text), or None.
    Faults and e-stops (severity 900, 800) as they latch; the machine's own start in ESTOP
    is not news."""
    state, fault = after.get("state"), after.get("fault")
    if state == before.get("state") or not before:
        return None
    if state == "FAULT":
        return "fault", 900, f"fault: {fault}"
    if state == "ESTOP":
        return "estop", 800, f"e-stop: {fault}"
    return None


def warning_for(before: dict[str, Any], after: dict[str, Any]) -> tuple[str, int, str] | None:
    """A job that ended with a model warning (the servo model no longer holds), once."""
    last, prior = after.get("last_job") or {}, before.get("last_job") or {}
    warning = last.get("model_warning")
    if not warning or not before or (last.get("started"), warning) == (
            prior.get("started"), prior.get("model_warning")):
        return None
    return "model-warning", 500, str(warning)
