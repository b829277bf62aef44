"""The web panel's parts on their own: the preview's sampling (arcs within the chord
tolerance, NURBS on the curve, errors naming file and line), program names that cannot leave
the library, MDI's modal prefix, the token, Origin and Host checks, the listen address."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.config import load_config, parse_config
from controller.errors import ConfigError
from controller.http_listen import ListenError, is_loopback, parse_listen
from controller.interpreter.program import position_at_line, program_nurbs
from controller.operator.web import guard
from controller.operator.web.library import Library, LibraryError, check_name
from controller.operator.web.mdi import MdiError, MdiSession, check_text, user_message
from controller.operator.web.preview import CHORD_MM, program_preview

REPO = Path(__file__).resolve().parents[2]
CONFIG = load_config(str(REPO / "config" / "xy_table.yaml"))


@settings(max_examples=40, deadline=None)
@given(r_mm=st.floats(0.5, 60.0), a0=st.floats(-math.pi, math.pi),
       sweep=st.floats(0.05, 2 * math.pi - 0.05), clockwise=st.booleans())
def test_an_arc_is_sampled_on_its_circle_within_the_chord_tolerance(
        tmp_path_factory: pytest.TempPathFactory, r_mm: float, a0: float, sweep: float,
        clockwise: bool) -> None:
    cx, cy = 70.0, 60.0
    a1 = a0 - sweep if clockwise else a0 + sweep
    x0, y0 = cx + r_mm * math.cos(a0), cy + r_mm * math.sin(a0)
    x1, y1 = cx + r_mm * math.cos(a1), cy + r_mm * math.sin(a1)
    path = tmp_path_factory.mktemp("arc") / "arc.nc"
    path.write_text(f"G21 G90 G0 X{x0:.6f} Y{y0:.6f}\nG{2 if clockwise else 3} X{x1:.6f} "
                    f"Y{y1:.6f} I{cx - x0:.6f} J{cy - y0:.6f} F600\nM2\n")
    preview = program_preview(str(path), CONFIG)
    assert preview.error is None
    arc = next(p for p in preview.pieces if p["kind"] == "arc")
    pts = np.array(arc["points"])[:, :2]
    assert arc["line"] == 2
    assert np.allclose(pts[0], (x0, y0), atol=2e-4) and np.allclose(pts[-1], (x1, y1), atol=2e-4)
    assert np.allclose(np.hypot(pts[:, 0] - cx, pts[:, 1] - cy), r_mm, atol=2e-4)
    mids = (pts[1:] + pts[:-1]) / 2  # the chord's middle is where it leaves the arc most
    sagitta = r_mm - np.hypot(mids[:, 0] - cx, mids[:, 1] - cy)
    assert sagitta.max() <= CHORD_MM + 2e-4
    turn = np.unwrap(np.arctan2(pts[:, 1] - cy, pts[:, 0] - cx))
    assert np.all(np.diff(turn) < 0) if clockwise else np.all(np.diff(turn) > 0)


def test_a_nurbs_is_sampled_on_the_curve_and_errors_name_file_and_line(tmp_path: Path) -> None:
    naca = str(REPO / "nc_programs" / "naca2415.nc")
    preview = program_preview(naca, CONFIG)
    piece = preview.pieces[0]
    assert piece["kind"] == "nurbs" and piece["line"] == 4 and not preview.truncated
    curve = program_nurbs(naca, CONFIG)[0]
    dense = curve.evaluate(np.linspace(curve.u_start, curve.u_end, 20001), order=0)[0]
    for p in np.array(piece["points"])[:, :2]:
        assert np.hypot(*(dense - p).T).min() < 5e-3  # on the curve (the dense sampling's gap)
    assert preview.low_mm[0] == pytest.approx(-30.0, abs=0.01)  # chord 30 mm
    bad = tmp_path / "bad.nc"
    bad.write_text("G21 G90\nG1 X1 F600\nG1 X2 Q\n")
    preview = program_preview(str(bad), CONFIG)
    assert preview.error is not None and f"{bad}:3:" in preview.error
    assert [p["line"] for p in preview.pieces] == [2]  # what was read before the error


@settings(max_examples=200, deadline=None)
@given(name=st.text(min_size=0, max_size=120))
def test_a_program_name_never_leaves_the_library(tmp_path_factory: pytest.TempPathFactory,
                                                 name: str) -> None:
    state = tmp_path_factory.mktemp("state")
    library = Library(state)
    try:
        library.write(name, b"G0 X1\n")
    except LibraryError:
        assert sorted(os.listdir(state)) == ["programs"] and not os.listdir(library.folder)
        return
    assert os.listdir(library.folder) == [name] and check_name(name) == name
    assert sorted(os.listdir(state)) == ["programs"]


def test_the_library_follows_no_link_and_keeps_its_limits(tmp_path: Path) -> None:
    library = Library(tmp_path)
    secret = tmp_path / "secret.txt"
    secret.write_text("not a program")
    os.symlink(secret, library.folder / "link.nc")
    with pytest.raises(LibraryError):
        library.read("link.nc")
    assert [p["name"] for p in library.list()] == []
    library.delete("link.nc")  # the link itself, never what it points to
    assert secret.exists()
    for bad in ("../x.nc", "a/b.nc", ".hidden", "", "x" * 101, "a..b"):
        with pytest.raises(LibraryError):
            library.write(bad, b"G0\n")
    with pytest.raises(LibraryError) as exc:
        library.write("big.nc", b"x" * (16 * 1024 * 1024 + 1))
    assert exc.value.code == "too-large"


@settings(max_examples=40, deadline=None)
@given(inch=st.booleans(), incremental=st.booleans(), feed=st.floats(1.0, 3000.0),
       tolerance=st.one_of(st.none(), st.floats(0.001, 1.0)), motion=st.sampled_from(
           ["G0", "G1"]))
def test_the_mdi_prefix_brings_back_the_modes(tmp_path_factory: pytest.TempPathFactory,
                                              inch: bool, incremental: bool, feed: float,
                                              tolerance: float | None, motion: str) -> None:
    session = MdiSession(CONFIG)
    g64 = "G64" if tolerance is None else f"G64 P{tolerance:.4f}"
    lines = [f"{'G20' if inch else 'G21'} {'G91' if incremental else 'G90'} {g64} "
             f"F{feed:.3f}", motion]
    session.finished(lines)
    folder = tmp_path_factory.mktemp("mdi")

    def modes(text: str) -> dict:
        path = folder / "p.nc"
        path.write_text(text + "\n(end)\n")
        summary = position_at_line(str(path), CONFIG, text.count("\n") + 2).summary()
        return {k: summary[k] for k in ("feed_mm_s", "distance_mode", "units", "motion",
                                        "path_control")}

    expected = modes("\n".join(lines))
    got = modes("\n".join(session.prefix))
    assert got.pop("feed_mm_s") == pytest.approx(expected.pop("feed_mm_s"), rel=1e-6)
    tol_got = got["path_control"].pop("tolerance_mm")
    tol_expected = expected["path_control"].pop("tolerance_mm")
    assert (tol_got is None) == (tol_expected is None)
    if tol_got is not None:
        assert tol_got == pytest.approx(tol_expected, rel=1e-6)
    assert got == expected


def test_mdi_text_is_checked_and_its_errors_name_the_mdi_line() -> None:
    assert check_text(" G0 X1 \n\n Y2 ") == ["G0 X1", "Y2"]
    for bad in ("", "  \n ", None, "G0\x00X1", "%", "G0 X1\n" * 21, "X" * 257):
        with pytest.raises(MdiError):
            check_text(bad)
    assert user_message("MDI:4:3: error: Q word without a number") == \
        "MDI:2:3: error: Q word without a number"


def test_token_origin_host_and_listen_checks(tmp_path: Path) -> None:
    token = tmp_path / "token"
    token.write_text("0123456789abcdef0123\n")
    token.chmod(0o640)
    with pytest.raises(guard.TokenError, match="readable by others"):
        guard.read_token(str(token))
    token.chmod(0o600)
    assert guard.read_token(str(token)) == "0123456789abcdef0123"
    token.write_text("short\n")
    with pytest.raises(guard.TokenError, match="at least"):
        guard.read_token(str(token))
    assert guard.token_ok(None, None) and guard.token_ok("a" * 16, "a" * 16)
    assert not guard.token_ok("a" * 16, "b" * 16) and not guard.token_ok("a" * 16, None)
    assert guard.origin_ok(None, "127.0.0.1:8080")
    assert guard.origin_ok("http://127.0.0.1:8080", "127.0.0.1:8080")
    assert not guard.origin_ok("http://evil.example:8080", "127.0.0.1:8080")
    assert not guard.origin_ok("http://127.0.0.1:8081", "127.0.0.1:8080")
    assert not guard.origin_ok("null", "127.0.0.1:8080")
    for host in ("localhost:8080", "127.0.0.1:80", "[::1]:8080", "127.1.2.3"):
        assert guard.loopback_host(host), host
    for host in ("evil.example:8080", "10.0.0.1:8080", "", None, "localhost.evil.example"):
        assert not guard.loopback_host(host), host
    assert parse_listen(":8080") == ("127.0.0.1", 8080)
    assert parse_listen("[::1]:8080") == ("::1", 8080)
    for bad in ("8080", "host:", "host:0", "host:70000", "a b:80", ""):
        with pytest.raises(ListenError):
            parse_listen(bad)
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.2")


def test_the_http_keys_are_read_strictly() -> None:
    data = yaml.safe_load((REPO / "config" / "xy_table.yaml").read_text())
    data["service"] = {"http": "127.0.0.1:8080", "http_token_file": "/etc/cncd/token"}
    service = parse_config(data, "m.yaml").service
    assert (service.http, service.http_token_file) == ("127.0.0.1:8080", "/etc/cncd/token")
    for key, value in (("http", "8080"), ("http", 8080), ("http_token_file", "token"),
                       ("http_tokn_file", "/x")):
        data["service"] = {key: value}
        with pytest.raises(ConfigError) as exc:
            parse_config(data, "m.yaml")
        assert exc.value.key.startswith("service.http")


def test_the_page_ships_with_a_plain_install() -> None:
    """Every file the server serves is package data (a non-editable install has them)."""
    import fnmatch
    import tomllib

    from controller.operator.web.app import STATIC

    patterns = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"][
        "package-data"]["controller.operator.web"]
    for name in STATIC:
        assert (REPO / "controller" / "operator" / "web" / "static" / name).is_file()
        assert any(fnmatch.fnmatch(f"static/{name}", p) for p in patterns), name
