"""Which config `cncctl` and `cncd` read: --config, $CNC_CONFIG, /etc/cncd/cncd.yaml, built-in."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

import controller.config as config_module
from controller.config import CONFIG_ENV_VAR, resolve_config_path

REPO = Path(__file__).resolve().parents[2]
PROGRAM = str(REPO / "nc_programs" / "arcs.nc")
# cncctl with the system config moved to argv[1] (the test cannot write /etc)
WRAPPER = ("import sys; from pathlib import Path; import controller.config as c; "
           "c.SYSTEM_CONFIG_PATH = Path(sys.argv.pop(1)); "
           "from controller.operator.cli import main; sys.exit(main())")


def _named(tmp_path: Path, name: str) -> Path:
    path = tmp_path / f"{name}.yaml"
    text = (REPO / "config" / "xy_table.yaml").read_text()
    path.write_text(text.replace("name: xy_table", f"name: {name}"))
    return path


def _check(system: Path, *args: str, env_config: str | None = None) -> str:
    env = dict(os.environ)
    env.pop(CONFIG_ENV_VAR, None)
    if env_config is not None:
        env[CONFIG_ENV_VAR] = env_config
    proc = subprocess.run([sys.executable, "-c", WRAPPER, str(system), "check", *args, PROGRAM],
                          env=env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout.splitlines()[0]


def test_order_of_precedence_seen_by_cncctl(tmp_path: Path) -> None:
    system, from_env = _named(tmp_path, "etc_machine"), _named(tmp_path, "env_machine")
    flag = _named(tmp_path, "flag_machine")
    missing = tmp_path / "absent.yaml"
    assert _check(missing).endswith("(config xy_table)")
    assert _check(system).endswith("(config etc_machine)")
    assert _check(system, env_config=str(from_env)).endswith("(config env_machine)")
    assert _check(system, "--config", str(flag), env_config=str(from_env)).endswith(
        "(config flag_machine)")
    assert _check(system, env_config="xyz_mill").endswith("(config xyz_mill)")


def test_resolution_in_process(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    system = _named(tmp_path, "etc_machine")
    monkeypatch.delenv(CONFIG_ENV_VAR, raising=False)
    monkeypatch.setattr(config_module, "SYSTEM_CONFIG_PATH", system)
    assert resolve_config_path() == system
    monkeypatch.setenv(CONFIG_ENV_VAR, "xyz_mill")
    assert resolve_config_path().name == "xyz_mill.yaml"
    monkeypatch.setattr(config_module, "SYSTEM_CONFIG_PATH", tmp_path / "none.yaml")
    monkeypatch.delenv(CONFIG_ENV_VAR)
    assert resolve_config_path().name == "xy_table.yaml"


def test_cncd_resolves_through_the_same_function() -> None:
    from controller.operator.daemon import main as daemon_main

    assert daemon_main.load_config is config_module.load_config
    source = (REPO / "controller" / "operator" / "daemon" / "main.py").read_text()
    assert "load_config(args.config)" in source
