"""Every job watches the servo model from outside: `cncctl run` on the nominal sim card shows a
residual of the encoder's quantisation and no warning; on a plant whose poles are 30 % off
the model it warns with the figure and recommends `cncctl identify`, in its final lines, its
JSON, and through cncd in the journal and `cncctl status`. A warning, never a fault."""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

from tests.daemon_helpers import CNCCTL, REPO, running_cncd

NACA = str(REPO / "nc_programs" / "naca2415.nc")
OFF_MODEL = ("--drive-option", "plant_pole_pct=30")


def _run(*words: str) -> subprocess.CompletedProcess:
    return subprocess.run([*CNCCTL, "run", NACA, "--virtual-time", *words], capture_output=True,
                          text=True, timeout=120, cwd=REPO)


def test_on_the_nominal_card_the_residual_is_tiny_and_nothing_is_said() -> None:
    done = _run("--json")
    assert done.returncode == 0, done.stderr
    final = json.loads(done.stdout.splitlines()[-1])
    residual = final["model_residual_um"]
    assert residual["samples"] > 1000  # every frame of the 1.1 s job
    assert residual["max"] < 1.0 and residual["rms"] < 0.5  # 1 um pulses
    assert all(a["max"] <= 0.5 + 1e-6 for a in residual["axes"].values())
    assert set(residual["axes"]) == {"x", "y"}
    assert "model_warning" not in final
    text = _run()
    assert re.search(r"model residual max 0\.\d um", text.stdout)
    assert "WARNING" not in text.stdout and "identify" not in text.stdout


def test_a_plant_off_the_model_warns_with_the_figure_and_the_job_is_done() -> None:
    done = _run("--json", *OFF_MODEL)
    assert done.returncode == 0, done.stderr
    final = json.loads(done.stdout.splitlines()[-1])
    assert final["event"] == "done"  # a warning, not a fault
    worst = final["model_residual_um"]["max"]
    assert worst > 15.0  # over half the 30 um contour limit
    assert f"{worst:.1f} um" in final["model_warning"]
    assert "run `cncctl identify`" in final["model_warning"]
    text = _run(*OFF_MODEL)
    assert text.returncode == 0
    assert "WARNING: the servo model no longer holds" in text.stdout
    assert f"model residual max {worst:.1f} um" in text.stdout


def test_a_higher_share_keeps_the_same_figure_quiet(tmp_path: Path) -> None:
    config = (REPO / "config" / "xy_table.yaml").read_text()
    assert "runtime:\n" in config
    path = tmp_path / "quiet.yaml"
    path.write_text(config.replace("runtime:\n", "runtime:\n  model_watch_share: 1.5\n", 1))
    done = _run("--json", "--config", str(path), *OFF_MODEL)
    assert done.returncode == 0, done.stderr
    final = json.loads(done.stdout.splitlines()[-1])
    assert final["model_residual_um"]["max"] > 15.0 and "model_warning" not in final


def test_through_cncd_the_journal_and_status_carry_the_warning(tmp_path: Path) -> None:
    with running_cncd(tmp_path, *OFF_MODEL) as d:
        assert d.cncctl("reset").returncode == 0
        run = d.cncctl("run", NACA, "--json")
        assert run.returncode == 0, run.stderr
        final = json.loads(run.stdout.splitlines()[-1])
        assert final["event"] == "done" and "cncctl identify" in final["model_warning"]
        last = d.status()["last_job"]
        assert last["state"] == "DONE"
        assert last["model_warning"] == final["model_warning"]
        assert last["model_residual_um"]["max"] == final["model_residual_um"]["max"] > 15.0
        journal = json.loads((d.state_dir / "journal.json").read_text())
        assert journal["model_warning"] == final["model_warning"]
        shown = d.cncctl("status")
        assert shown.returncode == 0
        assert f"WARNING: {final['model_warning']}" in shown.stdout
        assert f"model residual max {final['model_residual_um']['max']:.1f} um" in shown.stdout
