"""The cncd systemd unit (systemd-analyze verify and security, as installed) and the installer
systemd/install.py, run into temporary roots: nothing is created on this machine's system."""

from __future__ import annotations

import base64
import hashlib
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
INSTALL = REPO / "systemd" / "install.py"
TEMPLATE = REPO / "systemd" / "cncd.service"
UNIT = "/etc/systemd/system/cncd.service"  # inside a root
SYSTEMD_ANALYZE = shutil.which("systemd-analyze")


def _analyze_version() -> int:
    if SYSTEMD_ANALYZE is None:
        return 0
    r = subprocess.run([SYSTEMD_ANALYZE, "--version"], capture_output=True, text=True)
    m = re.match(r"systemd (\d+)", r.stdout)
    return int(m[1]) if m else 0


# `verify --root=` and `security --offline=` came with systemd 250
needs_analyze = pytest.mark.skipif(_analyze_version() < 250,
                                   reason="systemd-analyze >= 250 not installed")  # fmt: skip


def install(root: Path, *args: str, ok: bool = True, env: dict | None = None):
    r = subprocess.run(
        [sys.executable, str(INSTALL), "--root", str(root), *args],
        capture_output=True, text=True, timeout=120, env=env,
    )  # fmt: skip
    if ok:
        assert r.returncode == 0, r.stdout + r.stderr
    return r


def unit_settings(text: str) -> dict[str, list[str]]:
    """Key -> values (in order) of a unit file; comments and section headers skipped."""
    out: dict[str, list[str]] = {}
    for line in text.splitlines():
        line = line.strip()
        if line and not line.startswith(("#", ";", "[")):
            key, _, value = line.partition("=")
            out.setdefault(key.strip(), []).append(value.strip())
    return out


def seconds(span: str) -> float:
    m = re.fullmatch(r"(\d+(?:\.\d+)?)(ms|s|min)?", span)
    assert m, span
    return float(m[1]) * {"ms": 1e-3, "s": 1.0, "min": 60.0, None: 1.0}[m[2]]


def systemd_root(root: Path, stub_cncd: bool = True) -> None:
    """Make root usable by `systemd-analyze --root`: the host's unit directory (verify needs
    sysinit.target and friends) and, unless pip installed the real one, a stub cncd."""
    host = next((p for p in (Path("/usr/lib/systemd/system"), Path("/lib/systemd/system"))
                 if p.is_dir()), None)  # fmt: skip
    if host is None:
        pytest.skip("no systemd unit directory on this machine")
    dest = root / "usr/lib/systemd/system"
    if not dest.exists():
        shutil.copytree(host, dest, symlinks=True)
    cncd = root / "opt/phcnc/venv/bin/cncd"
    if stub_cncd and not cncd.exists():
        cncd.write_text("#!/bin/sh\nexit 0\n")
        cncd.chmod(0o755)


def analyze(root: Path, *args: str, unit: str = UNIT) -> subprocess.CompletedProcess:
    return subprocess.run(
        [SYSTEMD_ANALYZE, *args, f"--root={root}", unit],
        capture_output=True, text=True, errors="replace", timeout=60,
    )  # fmt: skip


def verify(root: Path, unit: str = UNIT) -> tuple[int, str]:
    # --man=no: no Documentation= man page lookups. Any output at all is a finding: an unknown
    # key is only a warning with exit status 0 (reference note, section 3.1).
    r = analyze(root, "verify", "--man=no", unit=unit)
    return r.returncode, (r.stdout + r.stderr).strip()


@pytest.fixture(scope="module")
def staged(tmp_path_factory) -> tuple[Path, str]:
    """One install with --no-pip --no-system into a fresh root, and what it printed."""
    root = tmp_path_factory.mktemp("root")
    r = install(root, "--no-pip", "--no-system")
    return root, r.stdout


# -- the unit as installed -------------------------------------------------------------------


@needs_analyze
def test_installed_unit_verifies_without_any_output(staged):
    root, _ = staged
    systemd_root(root)
    rc, out = verify(root)
    assert rc == 0 and out == "", out


@needs_analyze
def test_verify_in_a_root_does_see_mistakes(staged, tmp_path):
    """The check above is not vacuous: in the same kind of root, verify reports an unknown key,
    a bad value and an ExecStart that is not there."""
    root, _ = staged
    systemd_root(root)
    good = (root / UNIT.lstrip("/")).read_text()
    bad = root / "etc/systemd/system/cncd-bad.service"
    bad.write_text(good.replace("WatchdogSec=2s", "WatchDogSec=2s\nRestart=sometimes")
                   .replace("/venv/bin/cncd", "/venv/bin/no-such-cncd"))  # fmt: skip
    try:
        rc, out = verify(root, "/etc/systemd/system/cncd-bad.service")
    finally:
        bad.unlink()
    assert "Unknown key" in out and "WatchDogSec" in out, out
    assert "restart specifier" in out and "sometimes" in out, out
    assert "no-such-cncd" in out and "not executable" in out, out
    assert rc != 0


@needs_analyze
def test_security_exposure_stays_low(staged):
    root, _ = staged
    systemd_root(root)
    r = analyze(root, "security", "--offline=true", "--no-pager")
    m = re.search(r"Overall exposure level for cncd\.service: (\d+\.\d+)", r.stdout)
    assert m, r.stdout + r.stderr
    # 2.0 when written (the reference unit scored 4.2); 3.0 leaves room, not a regression.
    assert float(m[1]) <= 3.0, r.stdout


def _syscalls(group: str, seen: set[str] | None = None) -> set[str]:
    """System calls of a seccomp group as this systemd defines it, nested groups expanded."""
    seen = set() if seen is None else seen
    r = subprocess.run([SYSTEMD_ANALYZE, "syscall-filter", group], capture_output=True,
                       text=True, timeout=30)  # fmt: skip
    calls: set[str] = set()
    for line in r.stdout.splitlines()[1:]:
        name = line.strip()
        if not name or name.startswith("#"):
            continue
        if name.startswith("@"):
            if name not in seen:
                seen.add(name)
                calls |= _syscalls(name, seen)
        else:
            calls.add(name)
    return calls


def test_unit_allows_realtime_serial_and_can():
    """What the daemon needs survives the hardening (checked on the template)."""
    s = unit_settings(TEMPLATE.read_text())
    one = {k: v[-1] for k, v in s.items()}
    assert one["Type"] == "notify" and one["NotifyAccess"] == "main"
    assert one["ExecStart"] == "@VENV@/bin/cncd --config @ETC@/cncd.yaml"
    assert one["WatchdogSec"] == "2s" and one["Restart"] == "on-failure"
    assert one["KillMode"] == "mixed"
    assert (one["User"], one["Group"]) == ("cncd", "cncd")
    assert "dialout" in one["SupplementaryGroups"].split()
    assert one["RuntimeDirectory"] == "cncd" and one["StateDirectory"] == "cncd"
    # the motion thread asks for SCHED_FIFO 80 (controller/runtime/processes.py)
    assert int(one["LimitRTPRIO"]) >= 80
    # the interpreter and generator set nice -10 (controller/motion/realtime.py)
    assert int(one["LimitNICE"]) <= -10
    assert one["LimitMEMLOCK"] == "infinity"
    for forbidden in ("RestrictRealtime", "PrivateDevices", "PrivateNetwork",
                      "CPUSchedulingPolicy", "MemoryDenyWriteExecute"):  # fmt: skip
        assert one.get(forbidden, "no") == "no", forbidden
    # AccessPolicy reads the client's /proc/PID/status (supplementary groups)
    assert one.get("ProtectProc", "default") == "default"
    assert one.get("ProcSubset", "all") == "all"
    families = one["RestrictAddressFamilies"].split()
    assert {"AF_UNIX", "AF_CAN"} <= set(families) and not families[0].startswith("~")
    allowed = set(s["DeviceAllow"])
    assert {"char-ttyUSB rw", "char-ttyACM rw"} <= allowed
    # the daemon's own SIGTERM budget must end before systemd's SIGKILL
    from controller.operator.daemon.main import STOP_TIMEOUT_S

    assert seconds(one["TimeoutStopSec"]) > STOP_TIMEOUT_S


@needs_analyze
def test_syscall_filter_keeps_realtime_calls():
    s = unit_settings(TEMPLATE.read_text())
    calls: set[str] = set()
    for value in s["SystemCallFilter"]:
        assert not value.startswith("~"), "a deny list: check it against the calls below"
        for group in value.split():
            calls |= _syscalls(group) if group.startswith("@") else {group}
    needed = {"sched_setscheduler", "sched_setaffinity", "mlockall", "socket", "ioctl",
              "clock_nanosleep", "prctl"}  # fmt: skip
    assert needed <= calls, needed - calls


# -- the installer -----------------------------------------------------------------------------


def test_installer_writes_unit_config_venv_and_plan(staged):
    root, out = staged
    unit = (root / UNIT.lstrip("/")).read_text()
    assert not re.search(r"@[A-Z_]+@", unit)
    assert "ExecStart=/opt/phcnc/venv/bin/cncd --config /etc/cncd/cncd.yaml\n" in unit
    cfg = root / "etc/cncd/cncd.yaml"
    assert cfg.read_bytes() == (REPO / "config/xy_table.yaml").read_bytes()
    assert (root / "opt/phcnc/venv/pyvenv.cfg").is_file()
    assert (root / "opt/phcnc/venv/bin/python").exists()
    assert os.readlink(root / "usr/local/bin/cncctl") == "/opt/phcnc/venv/bin/cncctl"
    plan = (root / "install-plan.txt").read_text().splitlines()
    commands = [line for line in plan if not line.startswith("#")]
    assert commands[0] == "groupadd --system cncd"
    assert commands[1].startswith("useradd --system --gid cncd --home-dir /var/lib/cncd")
    assert commands[1].endswith(" cncd")
    assert commands[2:] == ["systemctl daemon-reload", "systemctl enable cncd"]
    assert "install-plan.txt" in out


def test_installer_again_keeps_the_operators_config(tmp_path):
    install(tmp_path, "--no-pip", "--no-system")
    cfg = tmp_path / "etc/cncd/cncd.yaml"
    cfg.write_text("# this machine's config\n")
    unit = tmp_path / UNIT.lstrip("/")
    before = unit.read_text()
    r = install(tmp_path, "--no-pip", "--no-system")
    assert cfg.read_text() == "# this machine's config\n"
    assert "kept as it is" in r.stdout and "unchanged" in r.stdout
    assert unit.read_text() == before
    # a changed unit (an update) is replaced
    unit.write_text(before.replace("WatchdogSec=2s", "WatchdogSec=9s"))
    r = install(tmp_path, "--no-pip", "--no-system")
    assert "updated" in r.stdout and unit.read_text() == before


def test_installer_other_paths_and_no_link(tmp_path):
    install(tmp_path, "--no-pip", "--no-system", "--prefix", "/srv/cnc", "--etc", "/etc/mill",
            "--bin-dir", "")  # fmt: skip
    unit = (tmp_path / UNIT.lstrip("/")).read_text()
    assert "ExecStart=/srv/cnc/venv/bin/cncd --config /etc/mill/cncd.yaml\n" in unit
    assert (tmp_path / "etc/mill/cncd.yaml").is_file()
    assert (tmp_path / "srv/cnc/venv/pyvenv.cfg").is_file()
    assert not (tmp_path / "usr/local/bin/cncctl").exists()


def test_installer_refuses_a_path_the_unit_cannot_hold(tmp_path):
    r = install(tmp_path, "--no-pip", "--no-system", "--prefix", "/opt/my cnc", ok=False)
    assert r.returncode != 0 and "--prefix" in r.stderr
    assert not (tmp_path / UNIT.lstrip("/")).exists()


@pytest.mark.skipif(os.geteuid() != 0 or not (shutil.which("useradd") and shutil.which("groupadd")),
                    reason="useradd --prefix needs root")  # fmt: skip
def test_installer_creates_the_account_in_a_root_with_account_files(tmp_path):
    """As root, with --root DIR holding etc/passwd and etc/group, the account is made there
    (useradd --prefix); this machine's own account files stay as they were."""
    etc = tmp_path / "etc"
    etc.mkdir()
    (etc / "passwd").write_text("root:x:0:0:root:/root:/bin/sh\n")
    (etc / "group").write_text("root:x:0:\ndialout:x:20:\n")
    for name in ("shadow", "gshadow"):
        (etc / name).write_text("")
        (etc / name).chmod(0o640)
    host = {p: Path(p).read_bytes() for p in ("/etc/passwd", "/etc/group")}
    r = install(tmp_path, "--no-pip")
    user = [line for line in (etc / "passwd").read_text().splitlines() if line.startswith("cncd:")]
    assert len(user) == 1, user
    home, shell = user[0].split(":")[5:7]
    assert home == "/var/lib/cncd" and shell.endswith(("nologin", "false"))
    assert any(line.startswith("cncd:") for line in (etc / "group").read_text().splitlines())
    plan = (tmp_path / "install-plan.txt").read_text()
    assert "useradd" not in plan and "systemctl enable cncd" in plan
    assert "run: groupadd --system --prefix" in r.stdout
    r = install(tmp_path, "--no-pip")
    assert "user cncd exists" in r.stdout and "group cncd exists" in r.stdout
    assert {p: Path(p).read_bytes() for p in host} == host


def test_installer_notices_an_interpreter_user_cncd_cannot_run():
    """A venv made from a python under /root (pyenv) would not start as user cncd."""
    spec = importlib.util.spec_from_file_location("cncd_install", INSTALL)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    with tempfile.TemporaryDirectory() as tmp:  # not tmp_path: pytest's base is 0700
        base = Path(tmp)
        base.chmod(0o755)
        closed = base / "home"
        (closed / "bin").mkdir(parents=True)
        exe = closed / "bin" / "python3"
        exe.write_text("")
        exe.chmod(0o755)
        closed.chmod(0o700)
        if mod._closed_to_others(base) is not None:
            pytest.skip(f"{base} itself is closed to others")
        assert mod._closed_to_others(exe) == closed
        closed.chmod(0o755)
        assert mod._closed_to_others(exe) is None


def _wheel(dest: Path, version: str, cncd: bool) -> Path:
    """A tiny phcnc wheel (no dependencies), with or without the cncd console script."""
    dist = f"phcnc-{version}.dist-info"
    files = {
        "cncd_stub.py": "def main():\n    return 0\n",
        f"{dist}/METADATA": f"Metadata-Version: 2.1\nName: phcnc\nVersion: {version}\n",
        f"{dist}/WHEEL": "Wheel-Version: 1.0\nGenerator: test\nRoot-Is-Purelib: true\n"
                         "Tag: py3-none-any\n",
    }  # fmt: skip
    if cncd:
        files[f"{dist}/entry_points.txt"] = "[console_scripts]\ncncd = cncd_stub:main\n"
    record = []
    for name, text in files.items():
        digest = base64.urlsafe_b64encode(hashlib.sha256(text.encode()).digest()).rstrip(b"=")
        record.append(f"{name},sha256={digest.decode()},{len(text.encode())}")
    files[f"{dist}/RECORD"] = "\n".join([*record, f"{dist}/RECORD,,"]) + "\n"
    path = dest / f"phcnc-{version}-py3-none-any.whl"
    with zipfile.ZipFile(path, "w") as z:
        for name, text in files.items():
            z.writestr(name, text)
    return path


def test_installer_pip_path_with_a_wheel(tmp_path):
    """The pip step, offline: a package without the cncd script stops the install before the
    unit is written; with it, the unit's ExecStart is the real console script."""
    wheels = tmp_path / "wheels"
    wheels.mkdir()
    root = tmp_path / "root"
    env = {**os.environ, "PIP_NO_INDEX": "1"}
    r = install(root, "--no-system", "--wheel-from", str(_wheel(wheels, "0.0.1", cncd=False)),
                ok=False, env=env)  # fmt: skip
    assert r.returncode != 0 and "no 'cncd' console script" in r.stderr, r.stdout + r.stderr
    assert not (root / UNIT.lstrip("/")).exists()
    install(root, "--no-system", "--wheel-from", str(_wheel(wheels, "0.0.2", cncd=True)), env=env)
    cncd = root / "opt/phcnc/venv/bin/cncd"
    assert os.access(cncd, os.X_OK)
    if SYSTEMD_ANALYZE:
        systemd_root(root, stub_cncd=False)
        rc, out = verify(root)
        assert rc == 0 and out == "", out
