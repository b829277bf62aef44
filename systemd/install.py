"""Installer of the cncd service: system user, venv, machine config and systemd unit."""

# Standard library only: it runs with the system's python3 before any venv exists.
# Usage (see docs/install.md):
#   sudo python3 systemd/install.py [--root DIR] [--prefix /opt/phcnc] [--etc /etc/cncd]
#                                   [--no-system] [--no-pip | --wheel-from PATH]
# Every step checks what is there first, so running it again (for an update) is safe; it
# never overwrites an operator's config.

import argparse
import grp
import os
import pwd
import re
import shlex
import shutil
import stat
import subprocess
import sys
import tempfile
from pathlib import Path

SERVICE = "cncd"
USER = GROUP = "cncd"
STATE_DIR = "/var/lib/cncd"  # StateDirectory=cncd; also the user's home (never created here)
UNIT_DIR = "/etc/systemd/system"
PLAN_NAME = "install-plan.txt"
SOURCE = Path(__file__).resolve().parent.parent  # the repository this file belongs to
# Paths go into ExecStart= unquoted: no spaces, no systemd specifiers (%), no quotes.
SAFE_PATH = re.compile(r"/[A-Za-z0-9._+/-]*")
PLACEHOLDER = re.compile(r"@[A-Z_]+@")
COPY_IGNORE = shutil.ignore_patterns(
    ".git", ".venv", "venv", "build", "dist", "*.egg-info", "__pycache__", ".*_cache", ".hypothesis"
)


class Installer:
    """One run: paths, options and the commands left to run on the target (the plan)."""

    def __init__(self, args: argparse.Namespace):
        self.root = Path(args.root).resolve()
        self.staged = self.root != Path("/")  # --root DIR: installing into an image
        self.prefix = args.prefix
        self.etc = args.etc
        self.bin_dir = args.bin_dir
        self.source = Path(args.source).resolve()
        self.no_system = args.no_system
        self.no_pip = args.no_pip
        self.wheel_from = Path(args.wheel_from).resolve() if args.wheel_from else None
        self.python = args.python
        self.plan: list[str] = []
        self.venv = f"{self.prefix}/venv"

    # -- helpers ---------------------------------------------------------------------------

    def target(self, path: str) -> Path:
        """Where the absolute target-system path `path` is on this machine."""
        return self.root / path.lstrip("/")

    def say(self, text: str) -> None:
        print(f"install: {text}", flush=True)

    def run(self, cmd: list[str]) -> None:
        self.say("run: " + shlex.join(cmd))
        subprocess.run(cmd, check=True)

    def defer(self, cmd: list[str], why: str) -> None:
        self.plan.append(shlex.join(cmd))
        self.say(f"not run ({why}): {shlex.join(cmd)}")

    # -- steps -----------------------------------------------------------------------------

    def account(self) -> None:
        """The system group and user cncd (no home directory, no login shell)."""
        nologin = next(
            (p for p in ("/usr/sbin/nologin", "/sbin/nologin") if self.target(p).exists()),
            "/bin/false",
        )
        prefix: list[str] = []
        why = ""
        if self.no_system:
            why = "--no-system"
        elif self.staged:
            accounts = self.target("/etc/passwd").is_file() and self.target("/etc/group").is_file()
            if os.geteuid() == 0 and accounts:
                prefix = ["--prefix", str(self.root)]  # edits ROOT/etc/{passwd,group,...}
            else:
                why = "--root without root privileges" if accounts else "--root has no etc/passwd"
        groupadd = ["groupadd", "--system", *prefix, GROUP]
        useradd = [
            "useradd", "--system", *prefix, "--gid", GROUP, "--home-dir", STATE_DIR,
            "--no-create-home", "--shell", nologin, "--comment", "phcnc CNC daemon", USER,
        ]  # fmt: skip
        if why:
            self.defer(groupadd, why)
            self.defer(useradd, why)
            return
        if self.has_account("group", GROUP):
            self.say(f"group {GROUP} exists")
        else:
            self.run(groupadd)
        if self.has_account("passwd", USER):
            self.say(f"user {USER} exists")
        else:
            self.run(useradd)

    def has_account(self, db: str, name: str) -> bool:
        if self.staged:  # read the image's file, not this machine's name service
            lines = self.target(f"/etc/{db}").read_text().splitlines()
            return any(line.split(":", 1)[0] == name for line in lines)
        if db == "passwd":
            try:
                pwd.getpwnam(name)
            except KeyError:
                return False
            return True
        try:
            grp.getgrnam(name)
        except KeyError:
            return False
        return True

    def venv_and_package(self) -> None:
        """PREFIX/venv with this repository (or a given wheel) installed into it."""
        venv = self.target(self.venv)
        python = venv / "bin" / "python"
        if python.exists():
            self.say(f"venv {venv} exists")
        else:
            venv.parent.mkdir(parents=True, exist_ok=True)
            cmd = [self.python, "-m", "venv"]
            if self.no_pip:
                cmd.append("--without-pip")  # nothing will be installed: faster, offline
            self.run([*cmd, str(venv)])
        blocked = _closed_to_others(python.resolve())
        if blocked:
            self.say(
                f"warning: the venv's interpreter {python.resolve()} is not reachable for other "
                f"users ({blocked} lacks o+x): user {USER} could not start it; recreate the "
                f"venv with --python /usr/bin/python3 (remove {venv} first)"
            )
        if self.staged:
            self.say(
                f"note: a venv made under --root runs from {venv} only (its scripts name that "
                f"path); for a real machine run the installer there or in a chroot"
            )
        if self.no_pip:
            self.say(f"--no-pip: nothing installed into {venv}")
            return
        pip = [str(python), "-m", "pip", "install", "--upgrade"]
        if self.wheel_from is None:
            # Build from a clean copy: setuptools leaves build/ in the tree it builds, and a
            # module deleted from the repository would live on from there in later installs.
            with tempfile.TemporaryDirectory(prefix="phcnc-src-") as tmp:
                copy = Path(tmp) / "phcnc"
                shutil.copytree(self.source, copy, ignore=COPY_IGNORE, symlinks=True)
                self.say(f"building from a clean copy of {self.source}")
                self.run([*pip, str(copy)])
        elif self.wheel_from.is_dir():  # a directory of wheels: phcnc and its dependencies
            self.run([*pip, "--find-links", str(self.wheel_from), "phcnc"])
        else:
            self.run([*pip, str(self.wheel_from)])
        cncd = venv / "bin" / SERVICE
        if not os.access(cncd, os.X_OK):
            raise SystemExit(
                f"install: error: {cncd} is missing after pip install: the package has no "
                f"'{SERVICE}' console script, the unit would not start; stopped before writing it"
            )

    def config(self) -> None:
        """ETC/cncd.yaml from config/xy_table.yaml, only when there is none yet."""
        etc = self.target(self.etc)
        dest = etc / "cncd.yaml"
        if dest.exists():
            self.say(f"config {dest} exists: kept as it is")
            return
        etc.mkdir(parents=True, exist_ok=True)
        etc.chmod(0o755)
        shutil.copyfile(self.source / "config" / "xy_table.yaml", dest)
        dest.chmod(0o644)  # the daemon (user cncd) reads it; ProtectSystem keeps it read-only
        self.say(f"config {dest} created from config/xy_table.yaml: edit it for this machine")

    def unit(self) -> None:
        """The unit with @VENV@ and @ETC@ filled in."""
        text = (self.source / "systemd" / "cncd.service").read_text()
        text = text.replace("@VENV@", self.venv).replace("@ETC@", self.etc)
        left = sorted(set(PLACEHOLDER.findall(text)))
        if left:
            raise SystemExit(f"install: error: unit template has unknown placeholders {left}")
        dest = self.target(f"{UNIT_DIR}/{SERVICE}.service")
        if dest.exists() and dest.read_text() == text:
            self.say(f"unit {dest} unchanged")
            return
        what = "updated" if dest.exists() else "created"
        dest.parent.mkdir(parents=True, exist_ok=True)
        tmp = dest.with_name(dest.name + ".tmp")
        tmp.write_text(text)
        tmp.chmod(0o644)
        tmp.replace(dest)
        self.say(f"unit {dest} {what}")

    def cncctl_link(self) -> None:
        """BIN_DIR/cncctl -> PREFIX/venv/bin/cncctl, so operators have cncctl on their PATH."""
        if not self.bin_dir:
            return
        link = self.target(f"{self.bin_dir}/cncctl")
        to = f"{self.venv}/bin/cncctl"  # a path on the target system
        if link.is_symlink() and os.readlink(link) == to:
            self.say(f"link {link} exists")
        elif link.exists() or link.is_symlink():
            self.say(f"warning: {link} exists and is not a link to {to}: left alone")
        else:
            link.parent.mkdir(parents=True, exist_ok=True)
            link.symlink_to(to)
            self.say(f"link {link} -> {to} created")

    def systemd(self) -> None:
        reload_, enable = ["systemctl", "daemon-reload"], ["systemctl", "enable", SERVICE]
        if self.no_system or self.staged:
            why = "--no-system" if self.no_system else "--root"
            self.defer(reload_, why)
            self.defer(enable, why)
            return
        if not os.path.isdir("/run/systemd/system"):  # a chroot or container build
            self.say("systemd is not running here: no daemon-reload; enabling offline")
            self.run(enable)
            return
        self.run(reload_)
        self.run(enable)
        active = subprocess.run(["systemctl", "is-active", "--quiet", SERVICE]).returncode == 0
        if active:  # never restarted here: that would stop a running job
            self.say(
                f"{SERVICE} is running the old version: when the machine is idle run "
                f"'systemctl restart {SERVICE}'"
            )
        else:
            self.say(f"start it with 'systemctl start {SERVICE}'")

    def write_plan(self) -> None:
        if not self.plan:
            return
        if not self.staged:
            self.say("commands not run (run them as root on this machine to finish):")
            for line in self.plan:
                print(f"  {line}")
            return
        path = self.root / PLAN_NAME
        header = (
            "# Commands systemd/install.py did not run for this root (--root, --no-system or\n"
            "# no privileges). Run them as root on the target machine, in this order.\n"
        )
        path.write_text(header + "".join(line + "\n" for line in self.plan))
        self.say(f"wrote the commands it did not run to {path}")

    def install(self) -> None:
        for name, value in (
            ("--prefix", self.prefix),
            ("--etc", self.etc),
            ("--bin-dir", self.bin_dir or "/"),
        ):
            if not SAFE_PATH.fullmatch(value):
                raise SystemExit(
                    f"install: error: {name} {value!r}: an absolute path of "
                    f"letters, digits and ._+/- is needed"
                )
        os.umask(0o022)  # user cncd must read the venv, whatever root's umask is
        if not self.staged and not self.no_system and os.geteuid() != 0:
            raise SystemExit("install: error: run as root (or use --root DIR / --no-system)")
        self.say(f"root {self.root}, prefix {self.prefix}, config {self.etc}, source {self.source}")
        self.account()
        self.venv_and_package()
        self.config()
        self.unit()
        self.cncctl_link()
        self.systemd()
        self.write_plan()
        self.say("done. Operators: usermod -aG cncd NAME (then log in again)")


def _closed_to_others(path: Path) -> Path | None:
    """The first of path and its directories that others may not search or execute (for
    example a python under /root), or None. Mode bits only: ACLs are not looked at."""
    for p in [*reversed(path.parents), path]:
        try:
            if not p.stat().st_mode & stat.S_IXOTH:
                return p
        except OSError:
            return p
    return None


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument(
        "--root",
        default="/",
        help="install into this directory as / (an image "
        "or a test); no systemctl, account commands only with --prefix support",
    )
    p.add_argument("--prefix", default="/opt/phcnc", help="venv goes to PREFIX/venv")
    p.add_argument("--etc", default="/etc/cncd", help="config directory (cncd.yaml)")
    p.add_argument(
        "--bin-dir", default="/usr/local/bin", help="where to link cncctl ('' for no link)"
    )
    p.add_argument(
        "--no-system",
        action="store_true",
        help="do not create the user and group, do not run systemctl",
    )
    pkg = p.add_mutually_exclusive_group()
    pkg.add_argument(
        "--no-pip", action="store_true", help="create the venv but install nothing into it"
    )
    pkg.add_argument(
        "--wheel-from",
        metavar="PATH",
        help="install this wheel, or phcnc from this directory of wheels, "
        "instead of building the repository",
    )
    p.add_argument("--source", default=str(SOURCE), help="the repository to install")
    p.add_argument("--python", default=sys.executable, help="interpreter for the venv (>= 3.11)")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    try:
        Installer(parse_args(argv)).install()
    except subprocess.CalledProcessError as e:
        cmd = shlex.join(str(c) for c in e.cmd)
        print(f"install: error: '{cmd}' failed (exit status {e.returncode}); the steps "
              f"before it are done, run the installer again after fixing the cause",
              file=sys.stderr)  # fmt: skip
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
