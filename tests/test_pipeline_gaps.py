"""Many short gaps: the samples that survive are analysed (issue 12, section 2)."""

import math
from dataclasses import replace

import numpy as np
import pytest
import statsmodels.api as sm
from numpy.testing import assert_allclose
from pipeline_synth import synth_circle

from imu_square.pipeline.filter import bridge_gaps
from imu_square.pipeline.sine_fit import fit_irls, robust_norm, sine_design
from imu_square.pipeline.squareness import AnalysisOptions, analyze
from imu_square.pipeline.uncertainty import cramer_rao
from imu_square.program import TestProgram

PROG = TestProgram(cycles_per_direction=4, dwell_s=1.0)
FAST = AnalysisOptions(bootstrap_n=50, grid_points=256)


def _lose(rec, fraction, mean_len, seed, clear=()):
    """Drop ``fraction`` of the samples in short gaps, none within the ``clear`` spans."""
    rng = np.random.default_rng(seed)
    t = rec.time_s
    keep = np.ones(rec.n_samples, dtype=bool)
    blocked = np.zeros(rec.n_samples, dtype=bool)
    for a, b in clear:
        blocked[(t >= a) & (t <= b)] = True
    while 1 - keep.mean() < fraction:
        start = int(rng.integers(1, rec.n_samples - mean_len - 1))
        stop = start + int(rng.integers(1, 2 * mean_len))
        if not blocked[start:stop].any():
            keep[start:stop] = False
    return replace(rec, accel=rec.accel[keep], time_ns=rec.time_ns[keep], seq=rec.seq[keep])


def _clear_of_motion_edges(truth, ramp_s=0.5, pad=0.5):
    return [
        (t - pad, t + ramp_s + pad) for b in truth["blocks"] for t in (b["t0"], b["t1"] - ramp_s)
    ]


def test_bridged_samples_follow_a_circle_and_are_marked_invalid():
    fs, f0 = 1000.0, 2.5
    t = np.arange(4000) / fs
    w = 2 * np.pi * f0
    x = np.column_stack([0.3 + 0.01 * t + 6.4 * np.cos(w * t), 6.4 * np.sin(w * t)])
    noise = np.random.default_rng(0).normal(0.0, 1e-4, x.shape)
    keep = np.ones(t.size, dtype=bool)
    keep[1000:1025] = keep[2000:2010] = False
    seq = np.flatnonzero(keep)
    gaps = [
        (int(i) + 1, int(j) - 1)
        for i, j in zip(
            np.flatnonzero(np.diff(seq) > 1), np.diff(seq)[np.diff(seq) > 1], strict=True
        )
    ]
    tb, xb, valid, breaks, spans = bridge_gaps(t[keep], (x + noise)[keep], gaps, f0)
    assert breaks == () and len(spans) == 2
    assert_allclose(tb, t, atol=1e-12)
    assert np.count_nonzero(~valid) == 35 and not valid[1000:1025].any()
    # a line plus the circle, predicted from ~130 noisy samples: within a few noise sd
    assert_allclose(xb[~valid], x[~valid], atol=5e-4)


def test_a_gap_longer_than_an_eighth_of_a_circle_is_not_bridged():
    fs, f0 = 1000.0, 2.5  # period 0.4 s: gaps up to 50 ms are bridged
    t = np.arange(3000) / fs
    x = np.column_stack([np.cos(2 * np.pi * f0 * t), np.zeros_like(t)])
    x += np.random.default_rng(1).normal(0.0, 1e-4, x.shape)
    keep = np.ones(t.size, dtype=bool)
    keep[1000:1060] = False
    _, _, valid, breaks, spans = bridge_gaps(t[keep], x[keep], [(1000, 60)], f0)
    assert breaks == (1000,) and spans == () and valid.all()


def test_prior_weights_leave_out_missing_points_exactly():
    rng = np.random.default_rng(3)
    phi = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    exog = sine_design(phi)
    y = 0.1 * np.cos(phi - 0.2) + rng.normal(0, 1e-3, phi.size)
    y[17] += 0.05  # a spike the bisquare rejects
    present = rng.random(phi.size) > 0.2
    masked = fit_irls(exog, np.where(present, y, np.nan), prior_weights=present.astype(float))
    subset = fit_irls(exog[present], y[present])
    assert_allclose(masked.params, subset.params, rtol=1e-12, atol=1e-15)
    assert_allclose(masked.bse, subset.bse, rtol=1e-10)
    assert_allclose(masked.scale, subset.scale, rtol=1e-12)
    assert masked.weights[0, 17] == 0.0 and not np.any(masked.weights[0, ~present])


def test_prior_weights_with_least_squares_are_weighted_least_squares():
    rng = np.random.default_rng(4)
    phi = np.linspace(0, 2 * np.pi, 120, endpoint=False)
    exog = sine_design(phi)
    counts = rng.integers(1, 6, phi.size).astype(float)  # cycles averaged per point
    y = 0.1 * np.cos(phi + 0.4) + rng.normal(0, 1e-3, phi.size) / np.sqrt(counts)
    ours = fit_irls(exog, y, robust_norm("ols"), prior_weights=counts)
    wls = sm.WLS(y, exog, weights=counts).fit()
    assert_allclose(ours.params[0], wls.params, rtol=1e-10)


def test_segmentation_measures_the_circle_across_many_gaps():
    # The phase step over an eighth of a period used to be taken over a sample lag
    # that straddled gaps: with a gap every second the rotation looked 34 % off.
    rec, truth = synth_circle(PROG, alpha=50e-6, density=7e-5, fs=200.0, seed=1)
    gappy = _lose(rec, 0.03, 5, seed=2, clear=_clear_of_motion_edges(truth))
    res = analyze(gappy, FAST)
    assert res.omega_rad_s == pytest.approx(PROG.omega_rad_s, rel=1e-4)


def test_many_short_gaps_keep_every_cycle_and_the_result():
    # 3 % lost in 5-sample gaps (25 ms at 200 Hz): each of the 8 cycles holds
    # several. The same noise, less data: the result moves by about
    # sqrt(lost / (1 - lost)) of one run's sd, and its uncertainty grows by
    # 1 / sqrt(1 - lost).
    d = 7e-5
    rec, truth = synth_circle(PROG, alpha=50e-6, eps_c=math.radians(2.1), density=d, fs=200.0)
    clean = analyze(rec, FAST)
    gappy_rec = _lose(rec, 0.03, 5, seed=5, clear=_clear_of_motion_edges(truth))
    gappy = analyze(gappy_rec, FAST)
    n_gaps = len(gappy_rec.gaps())
    assert n_gaps > 60
    assert gappy.cycles_used == {"ccw": 4, "cw": 4}
    assert gappy.quality["gaps"] == gappy.quality["gaps_bridged"] == n_gaps
    lost = gappy_rec.lost_samples / rec.n_samples
    crb = cramer_rao(d, 0.1, 8 * PROG.period_s)
    assert abs(gappy.squareness_rad - clean.squareness_rad) < 4 * crb * math.sqrt(lost / (1 - lost))
    # the floor counts the data left
    assert gappy.crb_rad / clean.crb_rad == pytest.approx(1 / math.sqrt(1 - lost), rel=0.01)
    assert abs(gappy.eps_c_rad - clean.eps_c_rad) < 3 * gappy.u_eps_c_rad
    assert abs(gappy.eps_c_stage2_rad) < math.radians(0.01), "stage 2 leaves out missing points"
