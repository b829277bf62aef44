"""PH replacement of corner zones: Hermite data, fit error and bisection (Table I analogue)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from gen_programs import lobed_nurbs
from nc_helpers import read_program_nurbs

import controller.generator.ph.fit as ph_fit
from controller.generator.corners.detection import detect_sharp_corners
from controller.generator.ph.fit import fit_single, fit_zone, foot_distances, zone_fit_report
from controller.geometry.nurbs import Nurbs

KAPPA_TH = 2450.0 / (3500.0 / 60.0) ** 2
E_MM = 1e-3



def circle(radius: float) -> Nurbs:
    pts = np.array([[radius, 0.0], [radius, radius], [0.0, radius]])
    return Nurbs(2, np.array([0.0, 0, 0, 1, 1, 1]), pts, np.array([1.0, math.sqrt(0.5), 1.0]))


def test_foot_distance_to_circle_is_radial() -> None:
    c = circle(5.0)
    angles = np.linspace(0.1, 1.4, 30)
    radii = 5.0 + np.linspace(-0.3, 0.3, 30)
    pts = np.column_stack((radii * np.cos(angles), radii * np.sin(angles)))
    dist = foot_distances(c, 0.0, 1.0, pts, angles / (math.pi / 2))
    np.testing.assert_allclose(dist, np.abs(radii - 5.0), atol=1e-12)


def test_quarter_circle_fit_bisects_to_the_limit() -> None:
    seg = fit_single(circle(1.0), 0.0, 1.0)
    # tangents of the rational circle are not of length pi/2, so only the shape bound is checked
    assert seg.fit_max_mm < 5e-2
    pieces = fit_zone(circle(1.0), 0.0, 1.0, 1e-6)
    assert all(p.fit_rms_mm <= 1e-6 for p in pieces)
    assert [p.u_start for p in pieces[1:]] == [p.u_end for p in pieces[:-1]]


def test_naca_leading_edge_table_one() -> None:
    naca = read_program_nurbs("naca2415.nc")
    (zone,) = detect_sharp_corners(naca, KAPPA_TH)
    one = fit_single(naca, zone.u_start, zone.u_end)
    assert one.fit_max_mm == pytest.approx(0.013, abs=0.001)  # docs/algorithms.md: 13 um
    assert one.ph.length_mm == pytest.approx(1.302, abs=0.001)
    assert one.ph.curvature(np.linspace(0, 1, 2001)).max() == pytest.approx(1.237, abs=0.001)
    pieces = fit_zone(naca, zone.u_start, zone.u_end, E_MM)
    assert len(pieces) > 1
    assert all(p.fit_rms_mm <= E_MM for p in pieces)
    assert pieces[0].u_start == zone.u_start and pieces[-1].u_end == zone.u_end
    for a, b in zip(pieces[:-1], pieces[1:], strict=True):  # G1 joints, same point
        assert a.u_end == b.u_start
        assert abs(a.ph.point(1.0)[0] - b.ph.point(0.0)[0]) < 1e-12
        ta, tb = a.ph.hodograph(1.0)[0], b.ph.hodograph(0.0)[0]
        assert abs(ta / abs(ta) - tb / abs(tb)) < 1e-12
    report = zone_fit_report(naca, zone.u_start, zone.u_end, E_MM)
    assert report.undivided_rms_mm > E_MM >= report.divided_rms_mm
    assert report.divided_max_mm < report.undivided_max_mm


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_foot_distances_settled_early_equal_fully_converged(seed: int,
                                                            monkeypatch: pytest.MonkeyPatch
                                                            ) -> None:
    """The early stop (FOOT_SETTLED plus a linear correction) loses nothing measurable: the
    PH fit samples of every sharp corner of a lobed NURBS, against Newton run to 1e-15."""
    ctrl, weights, knots = lobed_nurbs(seed)
    curve = Nurbs(3, knots, ctrl, weights)
    zones = detect_sharp_corners(curve, 0.5)
    assert zones
    for z in zones:
        ph = fit_single(curve, z.u_start, z.u_end).ph
        xi = np.linspace(0.0, 1.0, 257)
        pts = ph.point(xi)
        pts = np.column_stack((pts.real, pts.imag))
        guess = z.u_start + xi * (z.u_end - z.u_start)
        early = foot_distances(curve, z.u_start, z.u_end, pts, guess)
        monkeypatch.setattr(ph_fit, "FOOT_SETTLED", 1e-15)
        full = foot_distances(curve, z.u_start, z.u_end, pts, guess)
        monkeypatch.undo()
        np.testing.assert_allclose(early, full, rtol=0.0, atol=1e-12)


@pytest.mark.parametrize("seed", range(6))
def test_all_zones_points_at_once_equal_each_quintics_own(seed: int) -> None:
    """_fit_all measures every zone's quintic at its samples in one Horner scheme over all of
    them: bit for bit PhQuintic.point of each (the fit error and so the splits unchanged)."""
    from controller.geometry.ph_quintic import PhQuintic

    rng = np.random.default_rng(seed)
    phs = [PhQuintic.hermite(complex(*rng.normal(0, 20, 2)), complex(*rng.normal(0, 20, 2)),
                             complex(*rng.normal(0, 10, 2)), complex(*rng.normal(0, 10, 2)))
           for _ in range(int(rng.integers(1, 12)))]
    xi = np.linspace(0.0, 1.0, ph_fit._ERROR_SAMPLES)
    assert np.array_equal(ph_fit._points(phs, xi), np.array([ph.point(xi) for ph in phs]))


def _foot_distances_einsum(curve, u_start, u_end, pts, u_guess):  # type: ignore[no-untyped-def]
    """foot_distances as it was written on (N, 2) arrays with einsum: the reference."""
    u = u_guess.copy()
    lo, hi = np.broadcast_to(u_start, u.shape), np.broadcast_to(u_end, u.shape)
    settled = ph_fit.FOOT_SETTLED * np.maximum(hi - lo, 1e-300)
    for _ in range(ph_fit._FOOT_NEWTON_SWEEPS):
        d = curve.evaluate(u, 2)
        diff = d[0] - pts
        f = np.einsum("ni,ni->n", d[1], diff)
        fp = np.einsum("ni,ni->n", d[1], d[1]) + np.einsum("ni,ni->n", d[2], diff)
        step = np.where(fp > 0, f / np.where(fp > 0, fp, 1.0), 0.0)
        u_new = np.clip(u - step, lo, hi)
        moved = u - u_new
        if not np.any(np.abs(moved) > settled):
            diff -= moved[:, None] * d[1]
            return np.sqrt(np.einsum("ni,ni->n", diff, diff))
        u = u_new
    return np.linalg.norm(curve.evaluate(u, 0)[0] - pts, axis=1)


@pytest.mark.parametrize("seed", range(8))
def test_foot_distances_on_rows_equal_the_einsum_form(seed: int) -> None:
    """The foot-point Newton on separate x and y rows gives the einsum form's numbers bit for
    bit, on polynomial and rational NURBS and on a curve without evaluate_rows (a PH quintic)."""
    from controller.geometry.ph_quintic import PhQuintic

    rng = np.random.default_rng(seed)
    ctrl, weights, knots = lobed_nurbs(seed)
    curves = [Nurbs(3, knots, ctrl, weights), Nurbs(3, knots, ctrl, np.ones(len(weights))),
              PhQuintic.hermite(0j, complex(*rng.normal(0, 9, 2)), complex(*rng.normal(0, 5, 2)),
                                complex(*rng.normal(0, 5, 2)))]
    for curve in curves:
        a, b = sorted(rng.uniform(curve.u_start, curve.u_end, 2))
        u = rng.uniform(a, b, 400)
        pts = curve.evaluate(u, 0)[0] + rng.normal(0, 0.05, (400, 2))
        guess = np.clip(u + rng.normal(0, 0.01 * (b - a), 400), a, b)
        got = foot_distances(curve, a, b, pts, guess)
        assert np.array_equal(got, _foot_distances_einsum(curve, a, b, pts, guess))
