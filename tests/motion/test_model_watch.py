"""The model watch (motion/model_watch.ModelWatch): the servo model run on the frames sent,
against the encoder, in batches and with rows frames apart, gives the residual a one-pass
scipy filter gives; on its own plant the residual is the encoder's quantisation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from controller.config import load_config
from controller.motion import model_watch
from controller.motion.checks import RefHistory
from controller.motion.model_watch import ModelWatch
from controller.motion.stopping import REST_SPEED_MM_S
from controller.servo.model import contour_error_mm, discretise, mismatched_config
from drivers.sim.axes import SimAxes
from tests.daemon_helpers import REPO

CONFIG = load_config(str(REPO / "config/xy_table.yaml"))


def _circle_counts(pulse_mm: np.ndarray) -> np.ndarray:
    """A 10 mm circle at about 50 mm/s from rest to rest (ramped), then 200 frames at rest."""
    t = np.linspace(0.0, 1.0, 1500)
    s = 2 * np.pi * (t - np.sin(2 * np.pi * t) / (2 * np.pi))  # zero speed at both ends
    path = np.column_stack((10 * np.cos(s) - 10, 10 * np.sin(s)))
    path = np.vstack([path, np.repeat(path[-1:], 200, axis=0)])
    return np.rint(path / pulse_mm).astype(np.int64)


def _watched(pole_pct: float, every: int, chunk: int, misnumbered: int = 0) -> tuple[
        dict, np.ndarray, np.ndarray, RefHistory, np.ndarray]:
    """Frames sent `chunk` a cycle through a sim plant off the model by pole_pct; every
    `every`-th frame's feedback row fed to the watch (a serial card reports some), numbered
    `misnumbered` frames off."""
    pulse_mm = np.array([a.pulse_mm for a in CONFIG.axes])
    counts = _circle_counts(pulse_mm)
    start = counts[0]
    plant = SimAxes(mismatched_config(CONFIG, pole_pct), start)
    hist = RefHistory(1000, 2, CONFIG.sample_period_s)
    watch = ModelWatch(CONFIG, start)
    prev = start
    encoders, seqs = [], []
    for k0 in range(0, len(counts), chunk):
        block = counts[k0:k0 + chunk]
        pos_mm = block * pulse_mm
        hist.append(pos_mm, np.zeros(len(block)), np.ones(len(block), np.int64),
                    prev * pulse_mm, block)
        cmd, enc = plant.step(np.diff(np.vstack([prev, block]), axis=0))
        prev = block[-1]
        seq = np.arange(k0, k0 + len(block))
        shown = seq % every == 0
        watch.update(seq[shown] + misnumbered, cmd[shown], enc[shown], hist)
        seqs.append(seq[shown])
        encoders.append(enc[shown])
    return watch.summary_um(), np.concatenate(seqs), np.concatenate(encoders), hist, counts


def _one_pass(seq: np.ndarray, enc: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """The residual per reported row and axis, by scipy over the whole job at once."""
    pulse_mm = np.array([a.pulse_mm for a in CONFIG.axes])
    v = np.diff(counts, axis=0, prepend=counts[:1]) * pulse_mm / CONFIG.sample_period_s
    model = counts * pulse_mm
    for i, axis in enumerate(CONFIG.axes):
        servo = discretise(axis.servo, CONFIG.sample_period_s)
        model[:, i] -= lfilter(servo.b, servo.a, v[:, i])
    res = enc * pulse_mm - model[seq]
    return res


@pytest.mark.parametrize(("every", "chunk", "batch"), [(1, 2, 128), (3, 2, 128), (1, 7, 1),
                                                       (4, 5, 50)])
def test_batched_and_sparse_rows_give_the_one_pass_residual(
        every: int, chunk: int, batch: int, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(model_watch, "BATCH_ROWS", batch)
    summary, seq, enc, _, counts = _watched(30.0, every, chunk)
    res = _one_pass(seq, enc, counts)
    want = np.abs(res).max(axis=0) * 1e3
    got = [summary["axes"][n]["max"] for n in ("x", "y")]
    assert got == pytest.approx(want, abs=2e-3)
    assert summary["samples"] == len(seq)
    assert summary["axes"]["x"]["rms"] == pytest.approx(
        float(np.sqrt(np.mean(res[:, 0] ** 2))) * 1e3, abs=2e-3)
    assert max(got) > 10.0  # the plant is off the model: well above the quantisation


def test_the_contour_residual_is_the_normal_component_where_the_path_moves() -> None:
    summary, seq, enc, _, counts = _watched(30.0, 1, 2)
    res = _one_pass(seq, enc, counts)
    d = np.diff(counts, axis=0, prepend=counts[:1]) * 1e-3 / CONFIG.sample_period_s
    moving = np.hypot(d[:, 0], d[:, 1]) >= REST_SPEED_MM_S
    phi = np.where(moving, np.arctan2(d[:, 1], d[:, 0]), np.nan)
    normal = contour_error_mm(res[:, 0], res[:, 1], phi[seq])
    want_um = float(np.nanmax(np.abs(normal))) * 1e3
    assert summary["max"] == pytest.approx(want_um, abs=2e-3)
    assert summary["max"] < max(v["max"] for v in summary["axes"].values()) + 1e-9


def test_on_its_own_plant_the_residual_is_the_quantisation_and_no_warning() -> None:
    summary, *_ = _watched(0.0, 1, 2)
    assert all(v["max"] <= 0.5 + 1e-6 for v in summary["axes"].values())
    assert summary["max"] <= 0.71
    watch = ModelWatch(CONFIG, np.zeros(2, np.int64))
    assert watch.warning(summary) is None
    warned = watch.warning({**summary, "max": 15.2})
    assert warned is not None and "15.2 um" in warned and "cncctl identify" in warned
    assert watch.warning({**summary, "max": 14.9}) is None  # 0.5 of the 30 um limit


def test_rows_numbered_off_the_frames_sent_are_left_out_not_read_as_a_residual() -> None:
    summary, seq, *_ = _watched(0.0, 1, 2, misnumbered=1)
    # Only rows where the step counter stood still for a frame are compared (one frame off
    # there is within a pulse or two); a frame off at 50 mm/s would read 50 um.
    assert summary["unmatched"] > 1000 and summary["samples"] + summary["unmatched"] == len(seq)
    assert summary["max"] <= 2.0 and all(v["max"] <= 2.0 for v in summary["axes"].values())
