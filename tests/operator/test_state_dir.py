"""cncd distrusts its state directory: no link followed, only regular files read, nothing
owned or writable by others accepted, bad files kept aside and reported (a real cncd)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from daemon_helpers import CNCD, running_cncd

from controller.operator.daemon.state_dir import StateDir, StateDirError


def _state(tmp_path: Path) -> Path:
    state = tmp_path / "cncd-state"
    state.mkdir(mode=0o750)
    return state


def test_a_job_link_to_a_folder_is_removed_not_followed(tmp_path: Path) -> None:
    """Every file of the folder a `job-x` link named was deleted at start-up."""
    victim = tmp_path / "precious"
    victim.mkdir()
    (victim / "keep.txt").write_text("mine")
    state = _state(tmp_path)
    (state / "job-x").symlink_to(victim)
    (state / "approach-1.nc").symlink_to(victim / "keep.txt")
    with running_cncd(tmp_path) as d:
        assert d.status()["state"] == "ESTOP"
    assert (victim / "keep.txt").read_text() == "mine"
    assert not (state / "job-x").is_symlink() and not (state / "approach-1.nc").is_symlink()


def test_a_planted_temporary_link_is_never_written_through(tmp_path: Path) -> None:
    target = tmp_path / "target.txt"
    target.write_text("untouched")
    state = _state(tmp_path)
    for name in ("journal.tmp", ".journal.json.tmp", "offsets.json.tmp"):
        (state / name).symlink_to(target)
    with running_cncd(tmp_path) as d:
        assert d.cncctl("reset").returncode == 0
        assert d.cncctl("offset", "set", "G55", "X1").returncode == 0
    assert target.read_text() == "untouched"
    assert json.loads((state / "offsets.json").read_text())


@pytest.mark.parametrize("kind", ["dev-zero-link", "fifo", "garbage", "list"])
def test_a_bad_journal_or_offset_table_is_kept_aside_and_reported(tmp_path: Path,
                                                                  kind: str) -> None:
    """journal.json -> /dev/zero never finished starting (5.7 GB in 15 s); offsets.json as a
    FIFO blocked start-up for ever; a corrupt journal was read as {} without a word."""
    state = _state(tmp_path)
    for name in ("journal.json", "offsets.json"):
        path = state / name
        if kind == "dev-zero-link":
            path.symlink_to("/dev/zero")
        elif kind == "fifo":
            os.mkfifo(path, 0o600)
        else:
            path.write_text("{not json" if kind == "garbage" else "[1, 2]")
    with running_cncd(tmp_path) as d:
        status = d.status()
        problems = status["state_problems"]
        assert len(problems) == 2, problems
        assert any("journal.json" in p for p in problems)
        assert any("offsets.json" in p and "all zero" in p for p in problems)
        assert "state directory:" in d.log_text()
        shown = d.cncctl("status")
        assert "kept as journal.json.bad-" in shown.stdout, shown.stdout
    kept = sorted(p.name for p in state.iterdir() if ".bad-" in p.name)
    assert [k.split(".bad-")[0] for k in kept] == ["journal.json", "offsets.json"]


def _start_fails(tmp_path: Path, state: Path) -> str:
    done = subprocess.run([*CNCD, "--socket", str(tmp_path / "s.sock"), "--state-dir",
                           str(state)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 1, done.stderr
    return done.stderr


def test_a_state_directory_others_may_write_is_refused_naming_it(tmp_path: Path) -> None:
    state = _state(tmp_path)
    os.chmod(state, 0o777)
    assert f"state directory {state} is writable by others" in _start_fails(tmp_path, state)
    os.chmod(state, 0o750)
    (state / "journal.json").write_text("{}")
    os.chmod(state / "journal.json", 0o666)
    assert f"{state / 'journal.json'} is writable by others" in _start_fails(tmp_path, state)


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to give a file away")
def test_a_state_file_of_another_user_is_refused_naming_it(tmp_path: Path) -> None:
    state = _state(tmp_path)
    (state / "offsets.json").write_text("{}")
    os.chown(state / "offsets.json", 65534, -1)
    err = _start_fails(tmp_path, state)
    assert f"{state / 'offsets.json'} is owned by uid 65534" in err


def test_a_link_as_the_state_directory_is_refused(tmp_path: Path) -> None:
    real = _state(tmp_path)
    link = tmp_path / "link-state"
    link.symlink_to(real)
    with pytest.raises(StateDirError, match="a symbolic link"):
        StateDir(link)
    assert "a symbolic link" in _start_fails(tmp_path, link)
    assert sys.executable


def test_the_journal_keeps_the_last_identify_across_jobs_and_restarts(tmp_path: Path) -> None:
    from controller.operator.daemon.journal import Journal

    state = StateDir(tmp_path / "state")
    journal = Journal(state)
    journal.identify({"event": "done", "fits": {"x": {"fit_pct": 97.5}}})
    journal.start("part.nc", "0" * 64, 10)  # a job after it keeps it
    assert journal.entry["identify"]["event"] == "done"
    journal.identify({"event": "started", "axes": ["x"]})
    again = Journal(state).after_restart()  # killed while it moved
    assert again["identify"]["event"] == "interrupted"
    assert again["state"] == "INTERRUPTED" and again["program"] == "part.nc"
