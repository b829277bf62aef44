"""What `cncctl simulate` and `cncctl run --virtual-time` import: only what their path needs."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

# Run the command in a fresh interpreter, then list every module it holds (the modules a real
# `cncctl` process pays for before and while it works).
_PROBE = """
import json, sys
from controller.operator.cli import main
code = main(sys.argv[2:])
with open(sys.argv[1], "w") as fh:
    json.dump({"code": code, "modules": sorted(sys.modules)}, fh)
"""

# Neither command reaches these: other drives, the panel, OPC UA, identify, plots, scipy, and
# numpy.ma (np.unique imports it on first call; the planner uses a cheaper sorted unique),
# numpy.polynomial (the Gauss-Legendre tables are written out, controller/geometry).
NEVER = (
    "scipy",
    "canopen",
    "can",
    "serial",
    "asyncua",
    "aiohttp",
    "http.server",
    "matplotlib",
    "drivers.canopen",
    "drivers.serial",
    "controller.operator.identify",
    "controller.operator.web",
    "controller.operator.opcua",
    "controller.operator.daemon.server",
    "controller.servo.path_distance",
    "controller.servo.fit",
    "numpy.ma",
    "numpy.polynomial",
    "difflib",
)
# Only a run through cncd or a probing program needs these.
NOT_FOR_EMBEDDED_RUN = (
    "controller.operator.run.remote",
    "controller.operator.daemon.protocol",
    "controller.operator.run.probing",
    "controller.runtime.probe_run",
)


def _modules_of(words: list[str], tmp_path: Path) -> set[str]:
    """The modules a `cncctl WORDS` process held when the command returned (asserting exit 0)."""
    program = tmp_path / "one.nc"
    program.write_text("G1 X1 F600\n")
    out = tmp_path / "modules.json"
    env = dict(os.environ, CNCD_SOCKET=str(tmp_path / "no-daemon.sock"))
    argv = [w.replace("PROGRAM", str(program)) for w in words]
    subprocess.run(
        [sys.executable, "-c", _PROBE, str(out), *argv],
        env=env,
        check=True,
        stdout=subprocess.DEVNULL,
        timeout=120,
    )
    found = json.loads(out.read_text())
    assert found["code"] == 0
    return set(found["modules"])


def _heavy(modules: set[str], names: tuple[str, ...]) -> list[str]:
    """The names (or their submodules) present among modules."""
    return sorted(m for m in modules if any(m == n or m.startswith(n + ".") for n in names))


@pytest.mark.parametrize(
    "words", [["simulate", "PROGRAM", "--json"], ["run", "PROGRAM", "--virtual-time", "--json"]]
)
def test_a_command_imports_none_of_what_its_path_never_reaches(
    words: list[str], tmp_path: Path
) -> None:
    modules = _modules_of(words, tmp_path)
    assert "controller.generator.plan" in modules or "controller.generator.replan" in modules
    assert _heavy(modules, NEVER) == []


def test_an_embedded_run_leaves_the_daemon_client_and_probing_out(tmp_path: Path) -> None:
    modules = _modules_of(["run", "PROGRAM", "--virtual-time", "--json"], tmp_path)
    assert "drivers.sim" in modules  # the run did open its sim card
    assert _heavy(modules, NOT_FOR_EMBEDDED_RUN) == []
