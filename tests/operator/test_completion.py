"""`cncctl completion bash|zsh`: a script naming every command, that bash reads and uses."""

from __future__ import annotations

import shutil
import subprocess
import sys

import pytest

from controller.operator.cli import COMMANDS

CNCCTL = [sys.executable, "-m", "controller.operator.cli"]


def _script(shell: str) -> str:
    proc = subprocess.run([*CNCCTL, "completion", shell], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


@pytest.mark.parametrize("shell", ["bash", "zsh"])
def test_the_script_names_every_command(shell: str) -> None:
    text = _script(shell)
    for name, _, _ in COMMANDS:
        assert name in text
    assert "--virtual-time" in text and "--drive-option" in text


@pytest.mark.skipif(shutil.which("bash") is None, reason="no bash here")
def test_bash_reads_the_script_and_completes(tmp_path) -> None:  # type: ignore[no-untyped-def]
    path = tmp_path / "cncctl.bash"
    path.write_text(_script("bash"))
    assert subprocess.run(["bash", "-n", str(path)], timeout=30).returncode == 0
    probe = (f"source {path}\n"
             "COMP_WORDS=(cncctl si); COMP_CWORD=1; _shtab_cncctl; echo \"${COMPREPLY[@]}\"\n"
             "COMP_WORDS=(cncctl simulate --pl); COMP_CWORD=2; _shtab_cncctl; "
             "echo \"${COMPREPLY[@]}\"\n")
    out = subprocess.run(["bash", "-c", probe], capture_output=True, text=True, timeout=30)
    assert out.stdout.splitlines() == ["simulate simdrive", "--plot"], out.stderr


def test_an_unknown_shell_is_refused() -> None:
    proc = subprocess.run([*CNCCTL, "completion", "fish"], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 2 and "invalid choice" in proc.stderr
