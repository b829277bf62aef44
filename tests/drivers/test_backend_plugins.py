"""Drive backends from other packages: the `phcnc.drives` entry point, seen by a real cncctl."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from controller.backends import BUILTIN_BACKENDS
from drivers.registry import BUILTIN_BACKENDS as BUILTIN_CLASSES

REPO = Path(__file__).resolve().parents[2]
PROGRAM = str(REPO / "nc_programs" / "arcs.nc")

FAKE_MODULE = '''"""A drive backend of another package: the sim card, saying that it was built."""
import sys

from drivers.sim.card import SimCard


def make(config, **options):
    print(f"fake drive built with {sorted(options)}", file=sys.stderr)
    return SimCard(config, **options)
'''


def _plugin_dir(tmp_path: Path) -> Path:
    """A folder holding an installed-looking package: its dist-info names the entry point."""
    site = tmp_path / "site"
    info = site / "phcnc_fakedrive-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: phcnc-fakedrive\n"
                                   "Version: 0.1\n")
    (info / "entry_points.txt").write_text("[phcnc.drives]\nfakedrive = fake_drive:make\n")
    (site / "fake_drive.py").write_text(FAKE_MODULE)
    return site


def _config(tmp_path: Path, backend: str) -> Path:
    text = (REPO / "config" / "xy_table.yaml").read_text()
    assert "backend: sim" in text
    path = tmp_path / f"{backend}.yaml"
    path.write_text(text.replace("backend: sim", f"backend: {backend}"))
    return path


def _cncctl(site: Path, *args: str) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), str(REPO)]))
    env.pop("CNC_CONFIG", None)
    return subprocess.run([sys.executable, "-m", "controller.operator.cli", *args], env=env,
                          capture_output=True, text=True, timeout=120)


def test_builtin_names_agree() -> None:
    assert set(BUILTIN_BACKENDS) == set(BUILTIN_CLASSES)


def test_entry_point_backend_passes_the_check_and_drives_a_run(tmp_path: Path) -> None:
    site, config = _plugin_dir(tmp_path), _config(tmp_path, "fakedrive")
    check = _cncctl(site, "check", "--config", str(config), PROGRAM)
    assert check.returncode == 0, check.stderr
    run = _cncctl(site, "run", "--virtual-time", "--yes", "--config", str(config), PROGRAM)
    assert run.returncode == 0, run.stderr
    assert "fake drive built with ['realtime']" in run.stderr


def test_unknown_backend_names_the_key_and_the_known_ones(tmp_path: Path) -> None:
    site, config = _plugin_dir(tmp_path), _config(tmp_path, "nosuchdrive")
    check = _cncctl(site, "check", "--config", str(config), PROGRAM)
    assert check.returncode == 2
    assert "drive.backend" in check.stderr
    assert "canopen, fakedrive, serial, sim" in check.stderr
    assert "Traceback" not in check.stderr


def test_broken_entry_point_is_a_drive_error(tmp_path: Path) -> None:
    site, config = _plugin_dir(tmp_path), _config(tmp_path, "fakedrive")
    (site / "fake_drive.py").write_text("raise ImportError('needs libfoo')\n")
    run = _cncctl(site, "run", "--virtual-time", "--yes", "--config", str(config), PROGRAM)
    assert run.returncode == 2, run.stderr
    assert "needs libfoo" in run.stderr and "Traceback" not in run.stderr


def test_a_backend_registered_in_process_passes_the_config_check(tmp_path: Path) -> None:
    from controller.config import load_config
    from drivers.registry import make_drive, register_backend
    from drivers.sim.card import SimCard

    register_backend("inprocess_test_drive", SimCard)
    config = load_config(str(_config(tmp_path, "inprocess_test_drive")))
    assert config.drive.backend == "inprocess_test_drive"
    assert isinstance(make_drive(config, realtime=False), SimCard)
