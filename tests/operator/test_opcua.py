"""cncd's OPC UA server from outside: three real cncd, each with its server process on a free
port, read by one asyncua client in this process as a shop's dashboard reads them; a sim-card
job seen going idle -> running -> done, a fault, an e-stop and a model warning raising messages,
the methods only for a user the users file knows, a server that dies started again, and every
process stopped by its pid."""

from __future__ import annotations

import asyncio
import json
import os
import signal
import socket
import subprocess
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import yaml

asyncua = pytest.importorskip("asyncua")
from asyncua import Client, ua  # noqa: E402
from daemon_helpers import REPO, Cncd, children_of, running, start_cncd, start_run  # noqa: E402

from controller.operator.opcua.users import hash_password  # noqa: E402

MT = "http://opcfoundation.org/UA/MachineTool/"
MA = "http://opcfoundation.org/UA/Machinery/"
DI = "http://opcfoundation.org/UA/DI/"
OWN = "urn:phcnc:opcua"
SERVER_UP_S = 90.0  # the server imports six NodeSets: seconds on a loaded 2-core machine
PASSWORD = "s3cret-enough"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class Machine:
    daemon: Cncd
    endpoint: str
    serial: str
    fault_file: Path


def _config(tmp_path: Path, name: str, port: int, methods: bool) -> tuple[Path, str]:
    data = yaml.safe_load((REPO / "config/xy_table.yaml").read_text())
    serial = f"SN-{name}"
    opcua: dict[str, Any] = {"endpoint": f"opc.tcp://127.0.0.1:{port}/phcnc",
                             "manufacturer": "Test Works", "serial_number": serial,
                             "machine_name": name, "min_publish_ms": 20.0}
    if methods:
        users = tmp_path / f"{name}-users"
        users.write_text(f"op:{hash_password(PASSWORD, rounds=1000)}\n")
        users.chmod(0o600)
        key, cert = tmp_path / f"{name}-key.pem", tmp_path / f"{name}-cert.der"
        asyncio.run(_certificate(key, cert, name))
        opcua.update(methods=True, users_file=str(users), certificate=str(cert),
                     private_key=str(key))
    data["service"] = {"opcua": opcua}
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path, opcua["endpoint"]


async def _certificate(key: Path, cert: Path, name: str) -> None:
    """A self-signed server certificate: passwords then travel encrypted with it."""
    from asyncua.crypto.cert_gen import setup_self_signed_certificate
    from cryptography.x509.oid import ExtendedKeyUsageOID

    await setup_self_signed_certificate(key, cert, f"urn:phcnc:{name}", "127.0.0.1",
                                        [ExtendedKeyUsageOID.SERVER_AUTH], {"commonName": name})


def _wait_listening(endpoint: str, deadline_s: float) -> None:
    port = int(endpoint.rsplit(":", 1)[1].split("/")[0])
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), 0.2).close()
            return
        except OSError:
            assert time.monotonic() < deadline_s, f"no OPC UA server on {endpoint}"
            time.sleep(0.2)


def _opcua_pid(daemon: Cncd) -> int:
    kids = [pid for pid in children_of(daemon.proc.pid)
            if b"controller.operator.opcua.main" in Path(f"/proc/{pid}/cmdline").read_bytes()]
    assert len(kids) == 1, kids
    return kids[0]


def _stop(machines: list[Machine]) -> list[int]:
    """SIGTERM to each cncd by pid (it stops its server by pid); anything left is killed."""
    servers = []
    for m in machines:
        try:
            servers.append(_opcua_pid(m.daemon))
        except (AssertionError, OSError):
            pass
        if m.daemon.proc.poll() is None:
            m.daemon.proc.send_signal(signal.SIGTERM)
    left = []
    for m in machines:
        try:
            m.daemon.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            m.daemon.proc.kill()
            m.daemon.proc.wait(timeout=10)
        m.daemon.notify.sock.close()
    for pid in servers:
        if running(pid, wait_s=0.5):
            left.append(pid)
            os.kill(pid, signal.SIGKILL)
    return left


@pytest.fixture(scope="module")
def shop(tmp_path_factory: pytest.TempPathFactory) -> Iterator[list[Machine]]:
    tmp_path = tmp_path_factory.mktemp("opcua")
    machines: list[Machine] = []
    try:
        for name, methods in (("mill-a", False), ("mill-b", True), ("mill-c", False)):
            config, endpoint = _config(tmp_path, name, _free_port(), methods)
            fault = tmp_path / f"{name}-fault"
            # mill-c's plant is off its model (poles 30 % slower): its jobs warn.
            plant = ["--drive-option", "plant_pole_pct=30"] if name == "mill-c" else []
            daemon = start_cncd(tmp_path, "--config", str(config), "--drive-option",
                                f"drive_fault_file={fault}", *plant, name=name)
            machines.append(Machine(daemon, endpoint, f"SN-{name}", fault))
        deadline_s = time.monotonic() + SERVER_UP_S
        for m in machines:
            _wait_listening(m.endpoint, deadline_s)
            assert m.daemon.cncctl("reset").returncode == 0
        yield machines
    finally:
        left = _stop(machines)
    assert left == [], f"OPC UA servers outlived their cncd: {left}"


def _slow_program(tmp_path: Path, moves: int = 12) -> Path:
    program = tmp_path / "square.nc"
    lines = "".join(f"G1 X{x} Y{y}\n" for _ in range(moves // 4) for x, y in
                    ((4, 0), (4, 4), (0, 4), (0, 0)))
    program.write_text("G21 G90 G64 F900\n" + lines + "M2\n")
    return program


class Recorder:
    """Every data change and event an OPC UA subscription delivers, with its arrival time."""

    def __init__(self) -> None:
        self.changes: list[tuple[float, str, Any]] = []
        self.events: list[Any] = []
        self.names: dict[Any, str] = {}

    def datachange_notification(self, node: Any, val: Any, data: Any) -> None:
        self.changes.append((time.monotonic(), self.names[node.nodeid], val))

    def event_notification(self, event: Any) -> None:
        self.events.append(event)

    def values(self, name: str) -> list[Any]:
        return [v for _, n, v in self.changes if n == name]


async def _machine_node(client: Client) -> tuple[Any, dict[str, int]]:
    ns_array = await client.get_namespace_array()
    ns = {k: ns_array.index(uri) for k, uri in (("MT", MT), ("MA", MA), ("DI", DI),
                                                  ("OWN", OWN))}
    machines = await client.nodes.objects.get_child(f"{ns['MA']}:Machines")
    children = await machines.get_children()
    assert len(children) == 1
    return children[0], ns


async def _nodes(client: Client) -> tuple[dict[str, Any], Any, Any]:
    machine, ns = await _machine_node(client)
    mt, own = ns["MT"], ns["OWN"]
    channel = await machine.get_child([f"{mt}:Monitoring", f"{own}:Channel1"])
    program = await machine.get_child([f"{mt}:Production", f"{mt}:ActiveProgram"])
    nodes = {
        "ChannelState": await channel.get_child(f"{mt}:ChannelState"),
        "FeedOverride": await channel.get_child(f"{mt}:FeedOverride"),
        "X": await channel.get_child(f"{own}:ActualPositionX"),
        "Name": await program.get_child(f"{mt}:Name"),
        "Line": await program.get_child(f"{own}:LineNumber"),
        "Hash": await program.get_child(f"{own}:ProgramHash"),
        "ProgramState": await program.get_child([f"{mt}:State", "0:CurrentState"]),
        "OperationMode": await machine.get_child([f"{mt}:Monitoring", f"{mt}:MachineTool",
                                                   f"{mt}:OperationMode"]),
    }
    messages = await machine.get_child([f"{mt}:Notification", f"{mt}:Messages"])
    event_type = client.get_node(ua.NodeId(35, mt))  # NotificationEventType
    return nodes, messages, event_type


async def _subscribe(client: Client, period_ms: float = 20.0) -> tuple[Recorder, dict]:
    nodes, messages, event_type = await _nodes(client)
    rec = Recorder()
    rec.names = {node.nodeid: name for name, node in nodes.items()}
    sub = await client.create_subscription(period_ms, rec)
    await sub.subscribe_data_change(list(nodes.values()))
    await sub.subscribe_events(messages, event_type)
    return rec, nodes


async def _until(check: Any, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not check():
        assert time.monotonic() < deadline, f"not seen within {timeout_s} s: {what}"
        await asyncio.sleep(0.02)


def _finish(run: subprocess.Popen, timeout_s: float = 60.0) -> dict[str, Any]:
    out, err = run.communicate(timeout=timeout_s)
    return json.loads(out.strip().splitlines()[-1]) if out.strip() else {"stderr": err}


def test_one_client_reads_three_machines(shop: list[Machine]) -> None:
    async def read_all() -> list[tuple[str, str, str, int]]:
        found = []
        for m in shop:
            async with Client(m.endpoint) as client:
                machine, ns = await _machine_node(client)
                ident = await machine.get_child(f"{ns['DI']}:Identification")
                maker = await (await ident.get_child(f"{ns['DI']}:Manufacturer")).read_value()
                serial = await (await ident.get_child(f"{ns['DI']}:SerialNumber")).read_value()
                revision = await (await ident.get_child(f"{ns['DI']}:SoftwareRevision")
                                  ).read_value()
                # Found by its type, as a dashboard finds machines: MachineToolType.
                assert await machine.read_type_definition() == ua.NodeId(13, ns["MT"])
                nodes, _, _ = await _nodes(client)
                found.append(((await machine.read_browse_name()).Name, maker.Text, serial,
                              revision, await nodes["ChannelState"].read_value()))
        return found

    found = asyncio.run(read_all())
    assert [(name, serial) for name, _, serial, _, _ in found] == [
        ("mill-a", "SN-mill-a"), ("mill-b", "SN-mill-b"), ("mill-c", "SN-mill-c")]
    assert {maker for _, maker, _, _, _ in found} == {"Test Works"}
    assert all(rev.startswith("phcnc ") for _, _, _, rev, _ in found)
    assert {state for *_, state in found} == {2}  # ChannelState Reset: idle after reset


def test_a_job_goes_idle_running_done_and_a_fault_raises_a_message(
        shop: list[Machine], tmp_path: Path) -> None:
    m = shop[0]
    program = _slow_program(tmp_path)

    async def watch() -> tuple[Recorder, dict[str, Any], int]:
        async with Client(m.endpoint) as client:
            rec, nodes = await _subscribe(client)
            await _until(lambda: rec.values("ChannelState"), 5.0, "the first values")
            run = start_run(m.daemon, program)
            await _until(lambda: run.poll() is not None, 60.0, "the job's end")
            result = _finish(run)
            await _until(lambda: rec.values("ProgramState")[-1:] == [
                ua.LocalizedText("Ended")], 5.0, "Ended")
            # A second job, faulted by the drive mid-way: a message, and FAULT.
            before = len(rec.changes)
            run = start_run(m.daemon, program)
            await _until(lambda: any(n == "Line" and v > 3 for _, n, v in rec.changes[before:]),
                         30.0, "the second job at line 4")
            m.fault_file.write_text("")
            await _until(lambda: run.poll() is not None, 60.0, "the faulted job's end")
            _finish(run)
            await _until(lambda: rec.events, 15.0, "a message for the fault")
            m.fault_file.unlink()
            assert m.daemon.cncctl("reset").returncode == 0
            return rec, result, before

    rec, result, first_job_changes = asyncio.run(watch())
    assert result["event"] == "done", result
    states = [v for v in rec.values("ChannelState")]
    assert states[:3] == [2, 0, 2], states  # Reset -> Active -> Reset
    names = rec.values("Name")
    assert names[0] in (None, "") and names[-1].endswith("square.nc"), names
    lines = rec.values("Line")
    first_job = lines[:lines.index(max(lines)) + 1]
    assert len(set(first_job)) >= 8 and first_job == sorted(first_job), lines
    program_states = [v.Text for v in rec.values("ProgramState") if v is not None]
    assert program_states[:program_states.index("Ended") + 1][-2:] == ["Running", "Ended"]
    assert any(v == 1 for v in rec.values("OperationMode"))  # Automatic while it ran
    # The first job's X: the measured tool reaches the corner X4, within the contour limit
    # (30 um: the run's own figures give up to 20 um at these corners, and a sample can
    # catch it there); the second job's drive fault lets the axis coast.
    xs = [v for _, n, v in rec.changes[:first_job_changes] if n == "X"]
    assert max(xs) == pytest.approx(4.0, abs=0.03) and len(xs) > 10
    assert len(rec.values("Hash")[-1]) == 64
    fault = rec.events[0]
    assert fault.Identifier == "fault" and fault.Severity == 900, fault
    assert "fault" in fault.Message.Text.lower()


def test_an_estop_raises_a_message_and_nothing_is_writable(shop: list[Machine]) -> None:
    m = shop[2]

    async def watch() -> tuple[Recorder, ua.StatusCode]:
        async with Client(m.endpoint) as client:
            rec, nodes = await _subscribe(client)
            await _until(lambda: rec.values("ChannelState"), 5.0, "the first values")
            assert m.daemon.cncctl("estop").returncode == 0
            await _until(lambda: rec.events, 15.0, "a message for the e-stop")
            try:
                await nodes["FeedOverride"].write_value(ua.Variant(50.0, ua.VariantType.Double))
                code = ua.StatusCode(ua.StatusCodes.Good)
            except ua.UaStatusCodeError as exc:
                code = ua.StatusCode(exc.code)
            assert m.daemon.cncctl("reset").returncode == 0
            return rec, code

    rec, code = asyncio.run(watch())
    event = rec.events[0]
    assert event.Identifier == "estop" and event.Severity == 800
    assert "e-stop by operator" in event.Message.Text
    assert code.value == ua.StatusCodes.BadUserAccessDenied
    assert m.daemon.status()["feed_override_pct"] == 100.0


def test_methods_only_for_a_known_user_and_through_the_socket(
        shop: list[Machine], tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    m = shop[1]
    read_only = shop[0]

    async def call(endpoint: str, method: str, user: str | None = None,
                   password: str | None = None) -> Any:
        client = Client(endpoint)
        if user is not None:
            client.set_user(user)
            client.set_password(password or "")
        try:
            async with client:
                machine, ns = await _machine_node(client)
                channel = await machine.get_child([f"{ns['MT']}:Monitoring",
                                                   f"{ns['OWN']}:Channel1"])
                try:
                    return await channel.call_method(f"{ns['OWN']}:{method}")
                except ua.UaStatusCodeError as exc:
                    return ua.StatusCode(exc.code)
                except ua.UaError as exc:  # no such method
                    return exc
        except ua.UaStatusCodeError as exc:  # the log-in refused
            return ua.StatusCode(exc.code)

    async def scenario() -> dict[str, Any]:
        async with Client(m.endpoint) as watcher:
            rec, _ = await _subscribe(watcher)
            return await steps(rec)

    async def steps(rec: Recorder) -> dict[str, Any]:
        seen: dict[str, Any] = {}
        seen["idle hold"] = await call(m.endpoint, "Hold", "op", PASSWORD)
        run = start_run(m.daemon, _slow_program(tmp_path, moves=40))
        await _until(lambda: rec.values("ChannelState")[-1:] == [0], 30.0, "running")
        seen["anonymous"] = await call(m.endpoint, "Hold")
        seen["wrong"] = await call(m.endpoint, "Hold", "op", "wrong password")
        seen["read-only, user"] = await call(read_only.endpoint, "Hold", "op", PASSWORD)
        seen["read-only, anonymous"] = await call(read_only.endpoint, "Hold")
        caplog.clear()
        seen["hold"] = await call(m.endpoint, "Hold", "op", PASSWORD)
        seen["plain"] = [r.message for r in caplog.records if "plain-text" in r.message]
        await _until(lambda: rec.values("ChannelState")[-1:] == [1], 10.0, "held")
        seen["resume"] = await call(m.endpoint, "Resume", "op", PASSWORD)
        seen["abort"] = await call(m.endpoint, "Abort", "op", PASSWORD)
        seen["result"] = _finish(run)
        return seen

    seen = asyncio.run(scenario())
    assert seen["idle hold"].value == ua.StatusCodes.BadInvalidState  # the socket's not-running
    assert seen["anonymous"].value == ua.StatusCodes.BadUserAccessDenied
    assert seen["wrong"].value == ua.StatusCodes.BadUserAccessDenied
    # A read-only server takes no user names, and has no methods at all.
    assert seen["read-only, user"].value == ua.StatusCodes.BadIdentityTokenRejected
    assert seen["read-only, anonymous"].value == ua.StatusCodes.BadNoMatch  # no Hold there
    assert seen["hold"] in ("HOLDING", "HELD")
    assert seen["plain"] == []  # the password went encrypted with the server's certificate
    assert seen["resume"] == "RUNNING"
    assert seen["abort"] == "IDLE"
    assert seen["result"]["event"] == "aborted"
    assert "aborted by operator" in json.dumps(seen["result"])
    assert "OPC UA user 'op': abort -> IDLE" in m.daemon.log_text()


def test_a_job_on_a_machine_off_its_model_raises_a_model_warning(shop: list[Machine]) -> None:
    m = shop[2]

    async def watch() -> tuple[Recorder, dict[str, Any]]:
        async with Client(m.endpoint) as client:
            rec, _ = await _subscribe(client)
            await _until(lambda: rec.values("ChannelState"), 5.0, "the first values")
            run = start_run(m.daemon, REPO / "nc_programs/naca2415.nc")
            await _until(lambda: run.poll() is not None, 60.0, "the job's end")
            result = _finish(run)
            await _until(lambda: rec.events, 15.0, "a model warning")
            return rec, result

    rec, result = asyncio.run(watch())
    assert result.get("model_warning"), result
    event = rec.events[0]
    assert (event.Identifier, event.Severity) == ("model-warning", 500)
    assert event.Message.Text == result["model_warning"]


def test_a_server_that_dies_is_started_again(shop: list[Machine]) -> None:
    m = shop[2]
    first = _opcua_pid(m.daemon)
    os.kill(first, signal.SIGKILL)
    deadline = time.monotonic() + 20.0
    while True:
        kids = [pid for pid in children_of(m.daemon.proc.pid) if pid != first and
                b"opcua.main" in Path(f"/proc/{pid}/cmdline").read_bytes()]
        if kids:
            break
        assert time.monotonic() < deadline, "no second OPC UA server"
        time.sleep(0.1)
    assert f"(pid {first}) exited with -9; starting it again in 1 s" in m.daemon.log_text()
    assert m.daemon.status()["state"] == "IDLE"  # the machine did not notice
