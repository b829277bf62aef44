"""The excitation keeps its bounds, and the output-error fit recovers a known loop from it."""

from __future__ import annotations

import numpy as np
import pytest

from controller.config import ServoParams, load_config
from controller.servo.excitation import design
from controller.servo.fit import fit_axis, simulate_error_mm
from controller.servo.model import mismatched

T = 0.001
NOMINAL = load_config("config/xy_table.yaml").axes[0].servo


def _record(plant: ServoParams, quantise: bool) -> tuple[np.ndarray, np.ndarray]:
    exc = design(T, 58.3, 2450.0, 10.0)
    r = np.r_[np.zeros(50), exc.position_mm, np.zeros(300)] + 12.0
    r = np.rint(r / 0.001) * 0.001  # the frames are whole pulses
    p = r - simulate_error_mm(plant, np.diff(r, prepend=r[:1]) / T, T)
    return r, (np.rint(p / 0.001) * 0.001 if quantise else p)


def _response_gap(a: ServoParams, b: ServoParams) -> float:
    """Relative difference of two loops' tracking error on a fresh velocity signal."""
    v = np.diff(design(T, 58.3, 2450.0, 10.0, seed=7).position_mm, prepend=0.0) / T
    ea, eb = simulate_error_mm(a, v, T), simulate_error_mm(b, v, T)
    return float(np.linalg.norm(ea - eb) / np.linalg.norm(eb))


def test_excitation_stays_within_vmax_amax_and_window_and_ends_at_rest_even_faded() -> None:
    exc = design(T, 58.3, 2450.0, 1.0)
    for k0 in (0, 10, 200, 1500, len(exc.position_mm) - 100):
        x = np.r_[0.0, exc.position_mm[:k0], exc.fade_out(k0), 0.0, 0.0]
        v = np.diff(x) / T
        a = np.diff(v) / T
        assert np.abs(v).max() <= 58.3 and np.abs(a).max() <= 2450.0
        assert np.abs(x).max() <= 1.0 + 1e-12 and x[-3] == pytest.approx(0.0, abs=1e-12)
    lo, hi = exc.excursion_mm
    assert lo < 0 < hi and max(-lo, hi) <= 1.0 + 1e-12


@pytest.mark.parametrize("pole_pct,gain_pct", [(20.0, 0.0), (-20.0, 10.0), (0.0, 30.0)])
def test_fit_recovers_a_mismatched_loop_noise_free(pole_pct: float, gain_pct: float) -> None:
    plant = mismatched(NOMINAL, pole_pct, gain_pct)
    fit = fit_axis(*_record(plant, False), NOMINAL, T, 50)
    assert fit.problem is None and fit.fit_pct > 99.9
    assert _response_gap(fit.params, plant) < 1e-4
    # Normalised to a4 = 1, the coefficients themselves come back.
    got = np.array([fit.params.a0, fit.params.a1, fit.params.a3, fit.params.b2])
    want = np.array([plant.a0, plant.a1, plant.a3, plant.b2]) / plant.a4
    assert got == pytest.approx(want, rel=1e-3)


def test_fit_with_encoder_quantisation_explains_the_loop_far_better_than_the_nominal() -> None:
    plant = mismatched(NOMINAL, 20.0)
    fit = fit_axis(*_record(plant, True), NOMINAL, T, 50)
    assert fit.problem is None and fit.fit_pct > 90.0 and fit.fit_pct_in_force < 70.0
    assert fit.rms_um < 0.35  # the quantisation's own 0.29 um and little more
    assert _response_gap(fit.params, plant) < 0.1 * _response_gap(NOMINAL, plant)


def test_fit_on_sparse_samples_as_a_serial_card_reports_them() -> None:
    plant = mismatched(NOMINAL, -15.0, 10.0)
    r, p = _record(plant, True)
    idx = np.arange(0, len(r), 3)
    fit = fit_axis(r, p[idx], NOMINAL, T, 50, idx)
    assert fit.fit_pct > 90.0
    assert _response_gap(fit.params, plant) < 0.1 * _response_gap(NOMINAL, plant)


def test_a_record_without_the_loop_in_it_fits_badly() -> None:
    r, _ = _record(NOMINAL, True)
    noise = np.random.default_rng(1).normal(0.0, 0.02, len(r))  # 20 um of noise, no loop
    fit = fit_axis(r, r + noise, NOMINAL, T, 50)
    assert fit.fit_pct < 50.0


def test_mismatched_measured_samples_are_refused() -> None:
    r, p = _record(NOMINAL, True)
    with pytest.raises(ValueError):
        fit_axis(r, p[:5], NOMINAL, T, 50, np.arange(5))
