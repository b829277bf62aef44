"""The OPC UA server's parts that need no server: `service.opcua` read strictly, cncd refusing
the section without the library or with a users file others can read, the password hashes,
and cncd's states mapped onto the Machine Tools model's values."""

from __future__ import annotations

import copy
import os
from pathlib import Path
from typing import Any

import pytest
import yaml

from controller.config import ConfigError, load_config, parse_config
from controller.operator.daemon.opcua_child import OpcuaUnavailable, require_opcua
from controller.operator.opcua import values
from controller.operator.opcua.users import (
    UsersFileError,
    check_password,
    hash_password,
    read_users,
)

REPO = Path(__file__).resolve().parents[2]
BASE = yaml.safe_load((REPO / "config/xy_table.yaml").read_text())


def _config(opcua: dict[str, Any] | None) -> Any:
    data = copy.deepcopy(BASE)
    if opcua is not None:
        data["service"] = {"opcua": opcua}
    return parse_config(data, "m.yaml")


def test_off_by_default_and_the_section_read_strictly() -> None:
    assert _config(None).service.opcua is None
    cfg = _config({"endpoint": "opc.tcp://0.0.0.0:4840/phcnc"}).service.opcua
    assert cfg is not None and cfg.machine_name == "xy_table" and cfg.model == "xy_table"
    assert not cfg.methods and cfg.host_port == ("0.0.0.0", 4840)


@pytest.mark.parametrize("opcua, key", [
    ({}, "service.opcua.endpoint"),
    ({"endpoint": "http://host:4840"}, "service.opcua.endpoint"),
    ({"endpoint": "opc.tcp://host:99999"}, "service.opcua.endpoint"),
    ({"endpoint": "opc.tcp://h:4840", "endpont": 1}, "service.opcua.endpont"),
    ({"endpoint": "opc.tcp://h:4840", "methods": True}, "service.opcua.users_file"),
    ({"endpoint": "opc.tcp://h:4840", "users_file": "users"}, "service.opcua.users_file"),
    ({"endpoint": "opc.tcp://h:4840", "min_publish_ms": 1.0}, "service.opcua.min_publish_ms"),
    ({"endpoint": "opc.tcp://h:4840", "serial_number": "a\nb"},
     "service.opcua.serial_number"),
    ({"endpoint": "opc.tcp://h:4840", "certificate": "/c.der"}, "service.opcua.private_key"),
    ({"endpoint": "opc.tcp://h:4840", "certificate": "c.der", "private_key": "/k.pem"},
     "service.opcua.certificate"),
])
def test_a_bad_key_is_an_error_naming_it(opcua: dict[str, Any], key: str) -> None:
    with pytest.raises(ConfigError) as err:
        _config(opcua)
    assert key in str(err.value)


def test_cncd_refuses_the_section_without_the_library() -> None:
    config = _config({"endpoint": "opc.tcp://127.0.0.1:4840"})
    with pytest.raises(OpcuaUnavailable, match=r"pip install 'phcnc\[opcua\]'"):
        require_opcua(config, find_spec=lambda name: None)
    require_opcua(config)  # installed here
    require_opcua(_config(None), find_spec=lambda name: None)  # not asked for: no library
    missing = _config({"endpoint": "opc.tcp://127.0.0.1:4840", "certificate": "/nonexistent",
                       "private_key": "/nonexistent.pem"})
    with pytest.raises(OpcuaUnavailable, match="service.opcua.certificate: cannot read"):
        require_opcua(missing)


def test_a_users_file_others_can_read_is_refused(tmp_path: Path) -> None:
    users = tmp_path / "users"
    users.write_text(f"op:{hash_password('a password', rounds=1000)}\n")
    users.chmod(0o640)
    config = _config({"endpoint": "opc.tcp://127.0.0.1:4840", "methods": True,
                      "users_file": str(users)})
    with pytest.raises(UsersFileError, match="chmod 600"):
        require_opcua(config)
    users.chmod(0o600)
    require_opcua(config)
    link = tmp_path / "link"
    link.symlink_to(users)
    with pytest.raises(UsersFileError, match="cannot open"):
        read_users(str(link))
    users.write_text("op:plain-text-password\n")
    with pytest.raises(UsersFileError, match=":1:"):
        read_users(str(users))


def test_passwords_are_checked_against_their_hash() -> None:
    stored = hash_password("correct horse", rounds=1000)
    assert check_password("correct horse", stored)
    assert not check_password("correct hors", stored)
    assert not check_password("correct horse", stored.replace("1000", "999", 1))
    assert not check_password("x", "nonsense")


def test_the_shipped_configs_still_load_without_the_section() -> None:
    assert load_config(str(REPO / "config/xy_table.yaml")).service.opcua is None


def _seen(state: str, job: int | None = None, manual: bool = False,
          **status: Any) -> values.Seen:
    return values.Seen(status={"state": state, "job": job, "manual_move": manual, **status})


@pytest.mark.parametrize("state, job, manual, mode, channel, chmode, item", [
    ("ESTOP", None, False, "Manual", "Reset", "Automatic", "OutOfService"),
    ("IDLE", None, False, "Manual", "Reset", "Automatic", "NotExecuting"),
    ("CHECKING", 1, False, "Automatic", "Active", "Automatic", "Executing"),
    ("RUNNING", 1, False, "Automatic", "Active", "Automatic", "Executing"),
    ("HELD", 1, False, "Automatic", "Interrupted", "Automatic", "NotExecuting"),
    ("PAUSED", 1, False, "Automatic", "Interrupted", "Automatic", "NotExecuting"),
    ("RUNNING", 2, True, "Manual", "Active", "JogManual", "Executing"),
    ("HOMING", None, False, "Setup", "Active", "Reference", "Executing"),
    ("IDENTIFYING", None, False, "Service", "Active", "Other", "Executing"),
    ("FAULT", None, False, "Manual", "Reset", "Automatic", "OutOfService"),
])
def test_states_map_onto_the_companion_model(state: str, job: int | None, manual: bool,
                                             mode: str, channel: str, chmode: str,
                                             item: str) -> None:
    seen = _seen(state, job, manual)
    assert (values.operation_mode(seen), values.channel_state(seen), values.channel_mode(seen),
            values.item_state(seen)) == (mode, channel, chmode, item)


def test_the_program_runs_then_ends_as_the_journal_says() -> None:
    seen = _seen("RUNNING", 3, program="part.nc", program_sha256="ab" * 32)
    seen.job_started_s = {3: 1000.0}
    seen.progress = {"line": 17, "override_pct": 80.0, "feed_mm_s": 12.5,
                     "position_mm": [1.5, -2.0]}
    running = values.program_values(seen, 1004.0)
    assert (running["ProgramName"], running["Line"], running["Program"], running["RunTime"],
            running["JobIdentifier"]) == ("part.nc", 17, "Running", 4.0, "3")
    mon = values.monitoring_values(seen, ("x", "y"))
    assert (mon["FeedOverride"], mon["PositionX"], mon["PositionY"]) == (80.0, 1.5, -2.0)
    for outcome, state in (("DONE", "Ended"), ("ABORTED", "Aborted"), ("FAULT", "Aborted")):
        done = _seen("IDLE", last_job={"program": "part.nc", "state": outcome, "last_line": 40,
                                       "started": 1000.0, "updated": 1012.5})
        ended = values.program_values(done, 2000.0)
        assert (ended["Program"], ended["Line"], ended["RunTime"]) == (state, 40, 12.5)
    assert values.program_values(_seen("IDLE", last_job={}), 0.0) == {}


def test_faults_estops_and_model_warnings_raise_a_message_once() -> None:
    idle = {"state": "IDLE", "fault": None}
    assert values.message_for({}, {"state": "ESTOP", "fault": "start-up"}) is None
    assert values.message_for(idle, {"state": "FAULT", "fault": "X drive"}) == (
        "fault", 900, "fault: X drive")
    assert values.message_for(idle, {"state": "ESTOP", "fault": "button"})[0] == "estop"
    assert values.message_for({"state": "FAULT"}, {"state": "FAULT", "fault": "x"}) is None
    warned = {"last_job": {"started": 5.0, "model_warning": "the model no longer holds"}}
    assert values.warning_for({"last_job": {}}, warned) == (
        "model-warning", 500, "the model no longer holds")
    assert values.warning_for(warned, warned) is None


def test_the_users_command_writes_a_line_the_file_accepts(tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch,
                                                          capsys: pytest.CaptureFixture) -> None:
    from controller.operator.opcua import users

    monkeypatch.setattr("sys.stdin", _Lines("long enough password\n"))
    assert users.main(["op"]) == 0
    line = capsys.readouterr().out
    path = tmp_path / "users"
    path.write_text(line)
    os.chmod(path, 0o600)
    assert check_password("long enough password", read_users(str(path))["op"])
    monkeypatch.setattr("sys.stdin", _Lines("short\n"))
    assert users.main(["op"]) == 2


class _Lines:
    def __init__(self, text: str) -> None:
        self.text = text

    def isatty(self) -> bool:
        return False

    def readline(self) -> str:
        return self.text


def test_a_server_behind_applies_only_the_newest_progress() -> None:
    from controller.operator.opcua.bridge import coalesced

    messages = [{"event": "progress", "line": 1}, {"event": "state", "state": "HELD"},
                {"event": "progress", "line": 2}, {"id": 3, "ok": True},
                {"event": "progress", "line": 3}]
    assert coalesced(messages) == [{"event": "state", "state": "HELD"}, {"id": 3, "ok": True},
                                   {"event": "progress", "line": 3}]
    assert coalesced([]) == []


def test_power_on_counts_from_cncds_start() -> None:
    import time

    from controller.operator.opcua.view import started_epoch_s

    now = time.time()
    mine = started_epoch_s(os.getpid())
    assert now - 3600 < mine <= now  # this test process started within the hour
    assert started_epoch_s(1) <= mine  # init before it
    assert abs(started_epoch_s(2**22 + 7) - now) < 5  # no such process: now
