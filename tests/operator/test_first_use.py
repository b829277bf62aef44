"""The Quick start's install (`pip install -e .`): the commands need neither scipy nor
matplotlib, and `--plot` without matplotlib says how to install it, in one line."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
NACA = str(REPO / "nc_programs" / "naca2415.nc")
# Loaded by every Python process started with the folder on PYTHONPATH, forked or spawned.
SITECUSTOMIZE = '''"""Makes the packages in $PHCNC_TEST_BLOCK unimportable, as if not installed."""
import os
import sys
from importlib.abc import MetaPathFinder

BLOCKED = set(filter(None, os.environ.get("PHCNC_TEST_BLOCK", "").split(",")))


class Blocker(MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None


sys.meta_path.insert(0, Blocker())
'''


def cncctl_without(tmp_path: Path, blocked: str, *args: str,
                   cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    """A real cncctl in which the packages `blocked` (comma-separated) cannot be imported."""
    site = tmp_path / "block"
    site.mkdir(exist_ok=True)
    (site / "sitecustomize.py").write_text(SITECUSTOMIZE)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), str(REPO)]),
               PHCNC_TEST_BLOCK=blocked, MPLBACKEND="Agg")
    env.pop("CNC_CONFIG", None)
    return subprocess.run([sys.executable, "-m", "controller.operator.cli", *args], env=env,
                          capture_output=True, text=True, timeout=300, cwd=cwd)


def test_the_blocker_blocks(tmp_path: Path) -> None:
    proc = cncctl_without(tmp_path, "scipy", "--version")
    assert proc.returncode == 0
    site = tmp_path / "block"
    probe = subprocess.run([sys.executable, "-c", "import scipy"], capture_output=True,
                           text=True, env=dict(os.environ, PYTHONPATH=str(site),
                                               PHCNC_TEST_BLOCK="scipy"))
    assert "No module named 'scipy'" in probe.stderr


@pytest.mark.parametrize("args", [["check", NACA], ["simulate", NACA],
                                  ["run", "--virtual-time", NACA]])
def test_commands_run_without_scipy(tmp_path: Path, args: list[str]) -> None:
    proc = cncctl_without(tmp_path, "scipy", *args)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr


@pytest.mark.parametrize("command", ["simulate", "inspect"])
def test_plot_without_matplotlib_says_how_to_install_it(tmp_path: Path, command: str) -> None:
    png = tmp_path / "out.png"
    proc = cncctl_without(tmp_path, "matplotlib", command, "--plot", str(png), NACA)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "cncctl: error: --plot needs matplotlib: pip install 'phcnc[plot]'"]
    assert proc.stdout == "" and not png.exists()  # refused before any work


@pytest.mark.parametrize("command", ["simulate", "inspect"])
@pytest.mark.parametrize("name, says", [("x.txt", "cannot write .txt"),
                                        ("nofolder/x.png", "no such folder")])
def test_bad_plot_paths_are_refused_before_any_work(tmp_path: Path, command: str, name: str,
                                                    says: str) -> None:
    proc = cncctl_without(tmp_path, "", command, "--plot", str(tmp_path / name), NACA)
    assert proc.returncode == 2
    assert says in proc.stderr and "Traceback" not in proc.stderr
    assert proc.stdout == ""
