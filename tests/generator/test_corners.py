"""Sharp corner detection (eqs. 13-15) on the NACA 2415 and butterfly programs, zone widening."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from nc_helpers import read_program_nurbs

from controller.generator.corners.detection import detect_sharp_corners, joint_angle_rad, widen_zone
from controller.geometry.curves import ArcCurve, LineCurve

KAPPA_TH = 2450.0 / (3500.0 / 60.0) ** 2  # eq. 15 with Table III: 0.720 /mm



@pytest.fixture(scope="module")
def naca():  # type: ignore[no-untyped-def]
    return read_program_nurbs("naca2415.nc")


@pytest.fixture(scope="module")
def butterfly():  # type: ignore[no-untyped-def]
    return read_program_nurbs("butterfly.nc")


def test_naca_leading_edge_is_the_only_corner(naca) -> None:  # type: ignore[no-untyped-def]
    zones = detect_sharp_corners(naca, KAPPA_TH)
    assert len(zones) == 1
    z = zones[0]
    assert z.kappa_peak_per_mm == pytest.approx(1.30, abs=0.01)
    assert z.u_start == pytest.approx(0.48365, abs=2e-5)
    assert z.u_end == pytest.approx(0.52019, abs=2e-5)
    assert naca.curvature([z.u_start, z.u_end]) == pytest.approx([KAPPA_TH] * 2, abs=1e-9)
    assert abs(naca.curvature_derivative(z.u_peak)[0]) < 1e-6
    x, _ = naca.evaluate(z.u_peak, 0)[0, 0]
    assert x == pytest.approx(-30.0, abs=0.1)  # leading edge of the 30 mm chord


def test_butterfly_cusps_found(butterfly) -> None:  # type: ignore[no-untyped-def]
    zones = detect_sharp_corners(butterfly, KAPPA_TH)
    peaks = {round(z.u_peak, 3): z.kappa_peak_per_mm for z in zones}
    for u, kappa in ((0.256, 42.5), (0.744, 42.5), (0.450, 18.3), (0.550, 18.3)):
        assert peaks[u] == pytest.approx(kappa, rel=0.02)
    grid = np.linspace(0, 1, 200001)
    kappa = butterfly.curvature(grid)
    for z in zones:  # the zone is exactly where kappa > kappa_th around the peak
        inside = (grid > z.u_start) & (grid < z.u_end)
        assert kappa[inside].min() > KAPPA_TH - 1e-9
        assert kappa[inside].max() <= z.kappa_peak_per_mm + 1e-9
    above = kappa > KAPPA_TH
    covered = np.zeros_like(above)
    for z in zones:
        covered |= (grid >= z.u_start) & (grid <= z.u_end)
    assert not np.any(above & ~covered)


def test_widen_zone(naca, butterfly) -> None:  # type: ignore[no-untyped-def]
    z = detect_sharp_corners(naca, KAPPA_TH)[0]
    wide = widen_zone(naca, z, 0.5)
    assert wide.u_start < z.u_start and wide.u_end > z.u_end
    assert naca.curvature([wide.u_start, wide.u_end]) == pytest.approx([0.5, 0.5], abs=1e-9)
    # Two butterfly cusps close together: widening to a tiny level stops at the kappa minimum
    zones = detect_sharp_corners(butterfly, KAPPA_TH)
    left, right = zones[3], zones[4]  # peaks near u = 0.336 and 0.355
    w = widen_zone(butterfly, left, 1e-3)
    assert w.u_end < right.u_peak
    assert abs(butterfly.curvature_derivative(w.u_end)[0]) < 1e-3 * left.kappa_peak_per_mm
    assert widen_zone(butterfly, zones[0], 1e-3).u_start == 0.0  # clamped at the curve start


def test_line_and_arc_have_no_curvature_peak() -> None:
    assert detect_sharp_corners(LineCurve((0, 0), (1, 1)), KAPPA_TH) == []
    assert detect_sharp_corners(ArcCurve((0, 0), 0.5, 0.0, 1.0), KAPPA_TH) == []


def test_joint_angle() -> None:
    assert joint_angle_rad(np.array([1.0, 0]), np.array([0, 2.0])) == pytest.approx(math.pi / 2)
    assert joint_angle_rad(np.array([1.0, 0]), np.array([3.0, 0])) == 0.0
    assert joint_angle_rad(np.array([1.0, 1]), np.array([-1.0, -1])) == pytest.approx(math.pi)


def test_large_knot_values_give_the_same_corner(naca) -> None:  # type: ignore[no-untyped-def]
    """Knots in the hundreds (LinuxCNC corpus files count knots 0..600): the root finders
    must stop at the parameter's float resolution, not loop for ever."""
    from controller.geometry.nurbs import Nurbs

    shifted = Nurbs(naca.degree, naca.knots * 600.0 + 50.0, naca.control_points, naca.weights)
    (z,) = detect_sharp_corners(naca, KAPPA_TH)
    (zs,) = detect_sharp_corners(shifted, KAPPA_TH)
    assert zs.kappa_peak_per_mm == pytest.approx(z.kappa_peak_per_mm, rel=1e-9)
    assert (zs.u_peak - 50.0) / 600.0 == pytest.approx(z.u_peak, abs=1e-9)


@pytest.mark.parametrize("seed", range(12))
def test_peak_prefilter_never_drops_a_corner(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """Only peaks whose grid neighbours reach half of kappa_th are root-found; on sharp random
    lobes and NACA sections (thresholds from a tenth to twice the benchmark's) the zones are
    the ones found when every peak is root-found (to rounding: with few peaks dkappa/du is
    evaluated point by point, with many in one numpy call)."""
    from gen_programs import lobed_nurbs, lsq_nurbs, naca_points

    import controller.generator.corners.detection as corners
    from controller.geometry.nurbs import Nurbs

    if seed < 8:
        ctrl, weights, knots = lobed_nurbs(seed)
    else:
        ctrl, knots = lsq_nurbs(naca_points(("2415", "0012", "4412", "6409")[seed - 8], 30.0))
        weights = np.ones(len(ctrl))
    curve = Nurbs(3, knots, ctrl, weights)
    for th in (0.1, 0.5, 1.0, 2.0):
        found = corners.detect_sharp_corners(curve, th * KAPPA_TH)
        monkeypatch.setattr(corners, "PEAK_PREFILTER", 0.0)
        every_peak = corners.detect_sharp_corners(curve, th * KAPPA_TH)
        monkeypatch.undo()
        assert len(found) == len(every_peak)
        for z, ref in zip(found, every_peak, strict=True):
            assert (z.u_start, z.u_end) == (ref.u_start, ref.u_end)
            assert z.u_peak == pytest.approx(ref.u_peak, rel=1e-13, abs=1e-13)
            assert z.kappa_peak_per_mm == pytest.approx(ref.kappa_peak_per_mm, rel=1e-12)


def test_scalar_curvature_slope_matches_numpy(naca, butterfly) -> None:  # type: ignore[no-untyped-def]
    """The root finder's per-point dkappa/du equals the vectorised one, knots and zeros included."""
    for curve in (naca, butterfly):
        u = np.concatenate((np.linspace(curve.u_start, curve.u_end, 997), curve.knots))
        u = u[(u >= curve.u_start) & (u <= curve.u_end)]
        ref = curve.curvature_derivative(u)
        scalar = np.array([curve.curvature_derivative_scalar(x) for x in u.tolist()])
        np.testing.assert_allclose(scalar, ref, rtol=1e-11, atol=1e-9 * np.abs(ref).max())


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 7), st.integers(0, 2**32 - 1))
def test_scalar_root_finder_equals_the_array_one(curve_seed: int, seed: int) -> None:
    """With few brackets the peaks are root-found point by point in Python floats
    (detection._illinois); every root is bit for bit the one _bisect_all finds on arrays,
    random brackets of a lobed curve's dkappa/du (and their ends swapped in sign) included."""
    from gen_programs import lobed_nurbs

    import controller.generator.corners.detection as corners
    from controller.geometry.nurbs import Nurbs

    ctrl, weights, knots = lobed_nurbs(curve_seed)
    curve = Nurbs(3, knots, ctrl, weights)
    grid = corners.sample_grid(curve)
    dk = curve.curvature_derivative(grid)
    i = np.flatnonzero((dk[:-1] > 0) & (dk[1:] <= 0))
    rng = np.random.default_rng(seed)
    # the grid's brackets, and wider ones around them (more steps, Illinois halvings)
    lo = np.concatenate((grid[i], grid[np.maximum(i - rng.integers(1, 40, i.size), 0)]))
    hi = np.concatenate((grid[i + 1], grid[np.minimum(i + 1 + rng.integers(1, 40, i.size),
                                                      grid.size - 1)]))
    f_lo, f_hi = curve.curvature_derivative(lo), curve.curvature_derivative(hi)
    keep = (f_lo > 0) & (f_hi <= 0)
    lo, hi, f_lo, f_hi = lo[keep], hi[keep], f_lo[keep], f_hi[keep]
    assert lo.size  # a lobed curve has curvature peaks
    arrays = corners._bisect_all(lambda u: np.array([curve.curvature_derivative_scalar(x)
                                                     for x in u.tolist()]), lo, hi,
                                 f_lo=f_lo, f_hi=f_hi)
    scalar = [corners._illinois(curve.curvature_derivative_scalar, a, b, fa, fb)
              for a, b, fa, fb in zip(lo.tolist(), hi.tolist(), f_lo.tolist(), f_hi.tolist(),
                                      strict=True)]
    assert np.array_equal(arrays, np.array(scalar))
    assert np.all((arrays >= lo) & (arrays <= hi))


def test_scalar_root_finder_handles_flat_and_exact_steps() -> None:
    """A zero denominator (both ends equal) takes the midpoint, as numpy's inf does there, and
    a step that lands on the root exactly ends the search on it."""
    import controller.generator.corners.detection as corners

    def step(u: float) -> float:
        return 1.0 if u < 0.25 else -1.0

    lo, hi = np.array([0.0]), np.array([1.0])
    for f_lo, f_hi in ((1.0, 1.0), (1.0, -1.0), (3.0, -0.5)):
        ref = corners._bisect_all(lambda u: np.array([step(x) for x in u.tolist()]), lo, hi,
                                  f_lo=np.array([f_lo]), f_hi=np.array([f_hi]))
        assert corners._illinois(step, 0.0, 1.0, f_lo, f_hi) == ref[0]
    line = lambda u: 0.5 - u  # noqa: E731
    assert corners._illinois(line, 0.0, 1.0, 0.5, -0.5) == 0.5
