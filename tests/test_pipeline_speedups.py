"""The pipeline's fast paths give the numbers of the library calls they replace.

Each fast path (the phase fit by normal equations, in-place steps, Newton's
solver, ...) is held against the numpy/scipy call it replaces, and
the whole analysis is run twice, once with every fast path swapped back for
its reference, on several recordings: different seeds and effects, gaps, no
block markers, a fast circle. The two must agree to round-off: 1e-3 of the
Cramér-Rao bound for the squareness, far below anything the data can tell.
"""

import itertools
import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy import signal

from imu_square.pipeline import (
    align,
    newton,
    per_cycle,
    segment,
    squareness,
    stage2,
)
from imu_square.pipeline import filter as filter_module
from imu_square.pipeline import noise_floor as noise
from imu_square.pipeline import sine_fit as fit
from imu_square.pipeline.squareness import AnalysisOptions, analyze
from imu_square.program import TestProgram
from imu_square.simulate import SensorModel, simulate_run, with_effects
from imu_square.units import UG

SHORT = TestProgram(cycles_per_direction=4, dwell_s=1.0)
OPTIONS = AnalysisOptions(cutoff_hz=4.0, bootstrap_n=50)

floats = st.floats(-1e6, 1e6, allow_nan=False, width=64)


def _same(a, b):
    return (math.isnan(a) and math.isnan(b)) or a == b


@given(arrays(np.float64, st.integers(1, 50), elements=st.floats(-20, 20)), st.floats(1.0, 6.0))
def test_tukey_psi_and_its_derivative_are_statsmodels(z, c):
    norm = fit.robust_norm("tukey", c)
    psi, dpsi = fit._psi_and_deriv(norm, z)
    np.testing.assert_allclose(psi, norm.psi(z), rtol=1e-13, atol=1e-300)
    np.testing.assert_allclose(dpsi, norm.psi_deriv(z), rtol=1e-12, atol=1e-12)


def _rotation_reference(t, rel, period):
    """segment._rotation before it was made fast (commit 28f8832): complex phases, lstsq."""
    z = rel[:, 0] + 1j * rel[:, 1]
    dt = float(np.median(np.diff(t)))
    lag = max(1, round(period / 8 / dt))
    if z.size <= lag + 2:
        return 0.0, 1.0
    rates = np.angle(z[lag:] * np.conj(z[:-lag])) / (t[lag:] - t[:-lag])
    omega0 = float(np.median(rates))
    tm = 0.5 * (t[0] + t[-1])
    resid = np.angle(z * np.exp(-1j * omega0 * (t - tm)))
    dev = np.angle(np.exp(1j * (resid - np.median(resid))))
    good = np.abs(dev) < segment._MAX_PHASE_DEVIATION
    if np.count_nonzero(good) < 3:
        return omega0, 1.0
    u = t[good] - tm
    w = omega0 * u
    design = np.column_stack(
        [np.ones_like(u), u, np.cos(w), np.sin(w), np.cos(2 * w), np.sin(2 * w)]
    )
    slope = np.linalg.lstsq(design, dev[good], rcond=None)[0][1]
    return omega0 + float(slope), 1.0 - float(np.mean(good))


@settings(max_examples=60, deadline=None)
@given(
    omega=st.floats(-6.0, 6.0).filter(lambda w: abs(w) > 0.05),
    periods=st.floats(0.2, 12.0),
    ellipse=st.floats(0.0, 0.3),
    noise=st.floats(0.0, 0.5),
    gap=st.booleans(),
    seed=st.integers(0, 2**16),
)
def test_phase_fit_matches_lstsq(omega, periods, ellipse, noise, gap, seed):
    # Whole circles (condition about 3) down to a fifth of one (lstsq takes over),
    # off-circle samples and a gap: the same speed and off-circle fraction.
    rng = np.random.default_rng(seed)
    period = 2 * np.pi / abs(omega)
    t = np.arange(0.0, periods * period, 1e-3)
    if gap:
        t = np.delete(t, np.s_[t.size // 3 : t.size // 3 + t.size // 10])
    phi = omega * t + 0.3 + 0.05 * np.sin(2 * omega * t)
    rel = np.column_stack([(1 + ellipse) * np.cos(phi), np.sin(phi)])
    rel += noise * rng.standard_normal(rel.shape)
    fast, off = segment._rotation(t, rel, period)
    ref, off_ref = _rotation_reference(t, rel, period)
    assert off == pytest.approx(off_ref, abs=2 / t.size)  # a sample at 0.5 rad may flip
    assert fast == pytest.approx(ref, rel=1e-9, abs=1e-12)


def _phase_slope_basis_reference(u, dev, omega):
    """segment._phase_slope's normal equations with the basis stacked from temporaries."""
    half = max(abs(u[0]), abs(u[-1]), np.finfo(float).tiny)
    c, s = np.cos(omega * u), np.sin(omega * u)
    basis = np.stack([np.ones_like(u), u / half, c, s, c * c - s * s, 2 * c * s])
    return float(np.linalg.solve(basis @ basis.T, basis @ dev)[1] / half)


@settings(max_examples=30, deadline=None)
@given(
    omega=st.floats(-6.0, 6.0).filter(lambda w: abs(w) > 0.05),
    periods=st.floats(1.0, 12.0),
    seed=st.integers(0, 2**16),
)
def test_phase_slope_basis_in_place_is_bit_for_bit(omega, periods, seed):
    rng = np.random.default_rng(seed)
    u = np.arange(0.0, periods * 2 * np.pi / abs(omega), 1e-3)
    u -= 0.5 * u[-1]
    dev = 0.01 * u + 0.02 * np.sin(2 * omega * u) + 0.1 * rng.standard_normal(u.size)
    fast = segment._phase_slope(u, dev, omega)
    # the basis written in place gives the stacked temporaries' slope, to 1e-12 of the
    # 0.01 rad/s put in, a billionth of what 0.1 rad of noise lets the fit tell
    assert fast == pytest.approx(_phase_slope_basis_reference(u, dev, omega), abs=1e-14)


def _tukey_weights_reference(norm, z):
    u = np.square(z / norm.c)
    return np.where(u <= 1.0, np.square(1.0 - u), 0.0)


@given(
    arrays(
        np.float64,
        st.integers(1, 50),
        elements=st.floats(-20, 20) | st.sampled_from([np.nan, np.inf, -np.inf, 0.0, -0.0]),
    ),
    st.floats(1.0, 6.0),
)
def test_tukey_weights_in_place_are_bit_for_bit_and_statsmodels(z, c):
    norm = fit.robust_norm("tukey", c)
    fast = fit._weights(norm, z)
    np.testing.assert_array_equal(fast, _tukey_weights_reference(norm, z))
    scratch = z.copy()
    np.testing.assert_array_equal(fit._weights(norm, scratch, overwrite=True), fast)
    finite = np.isfinite(z)
    np.testing.assert_allclose(fast[finite], norm.weights(z[finite]), rtol=1e-13, atol=1e-300)


@pytest.mark.parametrize("complete", [True, False])
def test_circle_fits_without_covariance_are_the_same_fits(complete):
    rng = np.random.default_rng(11)
    phi = np.linspace(0, 2 * np.pi, 360, endpoint=False)
    ax = 1 + 3 * np.cos(phi - 0.01) + 0.05 * rng.standard_normal((40, phi.size))
    ay = -3 * np.sin(phi - 0.02) + 0.05 * rng.standard_normal((40, phi.size))
    ax[:, 7] += 2.0  # an outlier the robust norm weighs down
    prior = None if complete else (rng.random((40, phi.size)) > 0.05).astype(float)
    full = fit.fit_circle(phi, ax, ay, prior_weights=prior, maxiter=50, tol=1e-8)
    lean = fit.fit_circle(phi, ax, ay, prior_weights=prior, maxiter=50, tol=1e-8, covariance=False)
    for a, b in ((full.x, lean.x), (full.y, lean.y)):
        np.testing.assert_array_equal(a.params, b.params)
        np.testing.assert_array_equal(a.scale, b.scale)
        np.testing.assert_array_equal(a.iterations, b.iterations)
        assert np.all(np.isnan(b.cov)) and np.all(np.isnan(b.bse))
    np.testing.assert_array_equal(full.squareness, lean.squareness)
    np.testing.assert_array_equal(full.mean_phase, lean.mean_phase)
    assert np.all(np.isnan(lean.u_theta_x)) and np.all(np.isfinite(full.u_theta_x))


@settings(max_examples=50, deadline=None)
@given(
    arrays(
        np.float32,
        st.tuples(st.integers(1, 200), st.integers(1, 4)),
        elements=st.floats(-40, 40, width=32) | st.sampled_from([np.nan, np.inf, -np.inf, 20.0]),
    )
)
def test_clipped_samples_column_by_column_are_numpys_any(raw):
    expected = np.any(np.abs(raw) >= 0.999 * 20.0, axis=1)  # the call it replaces
    np.testing.assert_array_equal(filter_module.clipped_samples(raw, 20.0), expected)


def _periodogram_sum_reference(r, window):
    """noise._periodogram_sum from scipy.signal.welch, its scaling undone."""
    n = window.size
    _, p = signal.welch(r, fs=1.0, window=window, nperseg=n, axis=0)
    p = p * (1 + (r.shape[0] - n) // (n // 2)) * np.sum(window**2)
    p[1 : (n + 1) // 2] /= 2
    return p.sum(axis=1)


@settings(max_examples=30, deadline=None)
@given(
    n=st.integers(64, 3000),
    log_seg=st.integers(3, 6),
    axes=st.integers(1, 3),
    seed=st.integers(0, 99),
)
def test_periodogram_sum_is_scipys_welch(n, log_seg, axes, seed):
    r = np.random.default_rng(seed).standard_normal((n, axes)).cumsum(axis=0)
    window = signal.get_window("hann", 1 << log_seg)
    np.testing.assert_allclose(
        noise._periodogram_sum(r, window), _periodogram_sum_reference(r, window), rtol=1e-10
    )


def _lowpass_reference(data, cutoff_hz, order, sample_rate_hz, breaks=()):
    """filter.lowpass before (commit 28f8832): sosfiltfilt along axis 0."""
    sos = filter_module.design_lowpass(cutoff_hz, order, sample_rate_hz)
    data = np.asarray(data, dtype=np.float64)
    out = data.copy()
    edges = [0, *sorted(int(b) for b in breaks), data.shape[0]]
    for a, b in itertools.pairwise(edges):
        if b - a > 3 * (2 * sos.shape[0] + 1):
            out[a:b] = signal.sosfiltfilt(sos, data[a:b], axis=0)
    return out


@pytest.mark.parametrize("shape", [(5000,), (5000, 2), (5000, 3)])
@pytest.mark.parametrize("order", [1, 4])
def test_lowpass_of_all_channels_at_once_is_bit_for_bit(shape, order):
    data = np.random.default_rng(order).standard_normal(shape)[:, ...]
    breaks = [7, 1200, 3000]  # a stretch too short to filter, and three filtered
    fast = filter_module.lowpass(data, 20.0, order, 1000.0, breaks)
    assert fast.flags.c_contiguous
    np.testing.assert_array_equal(fast, _lowpass_reference(data, 20.0, order, 1000.0, breaks))


def _model_residual_reference(filtered, segmentation, cycles, mean_fit):
    """noise.model_residual before (commit 28f8832): np.interp with period=, axis by axis."""
    grid = cycles.phi_grid
    blocks = {b.plan.index: b for b in segmentation.blocks}
    t_s, raw, valid = filtered.t_s, filtered.raw, filtered.valid
    out = []
    for i, cyc in enumerate((cycles.ccw, cycles.cw)):
        params = [mean_fit.fit.x.params[i], mean_fit.fit.y.params[i]]
        means = [mean_fit.mean_x[i], mean_fit.mean_y[i]]
        has = mean_fit.counts[i] > 0
        remainders = []
        for p, m in zip(params, means, strict=True):
            rem = m - (p[0] + p[1] * np.cos(grid) + p[2] * np.sin(grid))
            remainders.append(np.interp(grid, grid[has], rem[has], period=2 * np.pi))
        for b, t0 in noise._spans(cyc, segmentation.period_s):
            lo, hi = np.searchsorted(t_s, t0)
            phi = segmentation.phi(blocks[b], t_s[lo:hi])
            c, s = np.cos(phi), np.sin(phi)
            res = np.empty((hi - lo, 2))
            for axis, (p, rem) in enumerate(zip(params, remainders, strict=True)):
                model = p[0] + (p[1] * c + p[2] * s) / mean_fit.gain
                model += np.interp(np.mod(phi, 2 * np.pi), grid, rem, period=2 * np.pi)
                res[:, axis] = raw[lo:hi, axis] - model
            ok = valid[lo:hi]
            edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
            out += [res[a:z] for a, z in zip(edges[::2], edges[1::2], strict=True)]
    return out


@pytest.mark.parametrize("name", ["servo", "short_gaps", "fast_circle"])
def test_model_residual_is_the_reference_to_round_off(name, monkeypatch):
    seen = []
    original = noise.model_residual

    def spy(*args):
        seen.append(args)
        return original(*args)

    monkeypatch.setattr(noise, "model_residual", spy)
    analyze(_case(name), OPTIONS)
    fast = original(*seen[0])
    ref = _model_residual_reference(*seen[0])
    assert len(fast) == len(ref) and len(fast) > 0
    for a, b in zip(fast, ref, strict=True):  # phi's whole turns off by ulps of ~1e3 rad
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


def _white_density_reference(residuals, sample_rate_hz):
    """noise.white_density before (commit e1a42b2), with numpy's medians."""
    r = np.concatenate(residuals, axis=0)
    sd = noise._MAD_TO_SD * np.median(np.abs(r - np.median(r, axis=0)), axis=0)
    return float(np.sqrt(np.mean(sd**2) / (sample_rate_hz / 2)))


@pytest.mark.parametrize("name", ["servo", "short_gaps"])
def test_white_density_in_place_is_bit_for_bit(name, monkeypatch):
    seen = []
    original = noise.model_residual
    monkeypatch.setattr(noise, "model_residual", lambda *a: seen.append(original(*a)) or seen[-1])
    analyze(_case(name), OPTIONS)
    residuals = seen[0]
    assert len(residuals) > (1 if name == "short_gaps" else 0)
    kept = [r.copy() for r in residuals]
    fast = noise.white_density(residuals, 1000.0)
    assert fast == _white_density_reference(residuals, 1000.0)
    for a, b in zip(residuals, kept, strict=True):  # the caller's residuals untouched
        np.testing.assert_array_equal(a, b)


@pytest.fixture
def reference_paths(monkeypatch):
    """Swap every fast path for the library call it replaces."""

    def use():
        monkeypatch.setattr(segment, "_rotation", _rotation_reference)
        monkeypatch.setattr(
            segment, "_magnitude", lambda r, out=None: np.hypot(r[:, 0], r[:, 1], out=out)
        )
        monkeypatch.setattr(noise, "_periodogram_sum", _periodogram_sum_reference)
        monkeypatch.setattr(noise, "model_residual", _model_residual_reference)
        monkeypatch.setattr(filter_module, "lowpass", _lowpass_reference)
        monkeypatch.setattr(
            segment, "_minus_row", lambda a, r, out=None: np.subtract(a, r, out=out)
        )
        monkeypatch.setattr(noise, "white_density", _white_density_reference)
        psi_and_deriv = lambda m, z, overwrite=False: (m.psi(z), m.psi_deriv(z))  # noqa: E731
        monkeypatch.setattr(fit, "_psi_and_deriv", psi_and_deriv)
        monkeypatch.setattr(newton, "_psi_and_deriv", psi_and_deriv)
        monkeypatch.setattr(fit, "_weights", lambda m, z, overwrite=False: m.weights(z))
        monkeypatch.setattr(per_cycle, "fit_newton", _irls_for_newton)
        monkeypatch.setattr(stage2, "fit_newton", _irls_for_newton)

    return use


def _irls_for_newton(exog, endog, start_params, norm, *, prior_weights=None, **kwargs):
    """IRLS from the same start, to its own tolerance: what Newton's solver replaces."""
    kwargs.pop("newton_tol", None)
    fitted = fit.fit_irls(
        exog, endog, norm, start_params=start_params, prior_weights=prior_weights, **kwargs
    )
    return fitted.params, np.atleast_2d(endog).shape[0]


def _drop_short_gaps(rec, fraction, seed):
    """Lose ``fraction`` of the samples in gaps of 1-9 samples."""
    rng = np.random.default_rng(seed)
    keep = np.ones(rec.n_samples, dtype=bool)
    while 1 - keep.mean() < fraction:
        start = int(rng.integers(1, rec.n_samples - 10))
        keep[start : start + int(rng.integers(1, 10))] = False
    return replace(rec, accel=rec.accel[keep], time_ns=rec.time_ns[keep], seq=rec.seq[keep])


def _case(name):
    sensor = SensorModel(noise_density_m_s2_rthz=100 * UG, flicker_corner_hz=0.5, eps_c_rad=0.1)
    if name == "servo":
        return simulate_run(SHORT, *with_effects(["servo_mismatch"], sensor=sensor), seed=3)[0]
    if name == "spikes_gravity":
        effects = ["reversal_spikes", "gravity_coupling", "sensor_thermal_drift"]
        return simulate_run(SHORT, *with_effects(effects, sensor=sensor), seed=4)[0]
    if name == "vibration_clock_no_events":
        effects = ["structural_vibration", "sample_clock_error", "servo_mismatch"]
        rec = simulate_run(SHORT, *with_effects(effects, sensor=sensor), seed=5)[0]
        return replace(rec, events=[])
    if name == "short_gaps":
        rec = simulate_run(SHORT, *with_effects(["servo_mismatch"], sensor=sensor), seed=6)[0]
        return _drop_short_gaps(rec, 0.02, seed=6)
    if name == "fast_circle":  # 2.5 m/s^2 (0.25 g) at 2.5 circles per second
        prog = TestProgram(radius_m=0.016, feed_m_per_s=0.2, cycles_per_direction=8, dwell_s=1)
        return simulate_run(prog, *with_effects(["backlash"], sensor=sensor), seed=7)[0]
    raise ValueError(name)


@pytest.mark.parametrize(
    "name", ["servo", "spikes_gravity", "vibration_clock_no_events", "short_gaps", "fast_circle"]
)
def test_analysis_equals_the_reference_paths(name, reference_paths):
    rec = _case(name)
    fast = analyze(rec, OPTIONS)
    reference_paths()
    ref = analyze(rec, OPTIONS)
    crb = ref.crb_rad
    assert abs(fast.squareness_rad - ref.squareness_rad) < 1e-3 * crb
    assert abs(fast.servo_mismatch_rad - ref.servo_mismatch_rad) < 1e-3 * crb
    assert abs(fast.eps_c_rad - ref.eps_c_rad) < 1e-3 * ref.u_eps_c_rad
    assert fast.period_s == pytest.approx(ref.period_s, rel=1e-12)
    assert fast.u_squareness_rad == pytest.approx(ref.u_squareness_rad, rel=1e-6)
    u_boot = ref.u_squareness_bootstrap_rad
    # Newton solves each resample to about 2e-4 of u, IRLS to 1e-10 m/s^2.
    assert fast.u_squareness_bootstrap_rad == pytest.approx(u_boot, rel=1e-3)
    assert fast.u_eps_c_rad == pytest.approx(ref.u_eps_c_rad, rel=1e-6)
    assert fast.crb_rad == pytest.approx(crb, rel=1e-9)
    assert fast.noise_density_m_s2_rthz == pytest.approx(ref.noise_density_m_s2_rthz, rel=1e-9)
    assert _same(fast.flicker_corner_hz, ref.flicker_corner_hz) or fast.flicker_corner_hz == (
        pytest.approx(ref.flicker_corner_hz, rel=1e-6)
    )
    assert fast.cycles_used == ref.cycles_used
    assert fast.quality.keys() == ref.quality.keys()
    for key, value in ref.quality.items():  # counts and flags equal, numbers to round-off
        if isinstance(value, float):
            assert _same(fast.quality[key], value) or fast.quality[key] == pytest.approx(
                value, rel=1e-9, abs=1e-12
            ), key
        else:
            assert fast.quality[key] == value, key
    np.testing.assert_allclose(fast.per_cycle["t_ccw_s"], ref.per_cycle["t_ccw_s"], atol=1e-9)
    np.testing.assert_allclose(fast.per_cycle["t_cw_s"], ref.per_cycle["t_cw_s"], atol=1e-9)


@pytest.mark.parametrize(
    ("cutoff", "order", "fs"), [(4.0, 1, 1000.0), (20.0, 4, 1000.0), (3, 2, 800)]
)
def test_lowpass_design_is_scipys_butter_and_a_copy(cutoff, order, fs):
    reference = signal.butter(order, cutoff, output="sos", fs=fs)
    first = filter_module.design_lowpass(cutoff, order, fs)
    first[:] = 0.0  # a caller's change does not reach the next caller
    np.testing.assert_array_equal(filter_module.design_lowpass(cutoff, order, fs), reference)


@pytest.mark.parametrize("name", ["servo", "short_gaps"])
def test_cycle_traces_from_contiguous_copies_are_bit_for_bit(name, monkeypatch):
    seen = []
    original = align.cycle_traces

    def spy(*args, **kwargs):
        seen.append((args, kwargs))
        return original(*args, **kwargs)

    monkeypatch.setattr(squareness, "cycle_traces", spy)
    analyze(_case(name), OPTIONS)
    args, kwargs = seen[0]
    fast = original(*args, **kwargs)
    with monkeypatch.context() as m:  # np.interp fed the strided, reversed views, as before
        m.setattr(align.np, "ascontiguousarray", lambda v: v)
        ref = original(*args, **kwargs)
    assert fast.ccw.n > 0 and fast.cw.n > 0
    for a, b in ((fast.ccw, ref.ccw), (fast.cw, ref.cw)):
        np.testing.assert_array_equal(a.x, b.x)
        np.testing.assert_array_equal(a.y, b.y)
        np.testing.assert_array_equal(a.valid, b.valid)
    assert fast.dropped == ref.dropped


@given(arrays(np.float64, st.tuples(st.integers(1, 40), st.just(2)), elements=st.floats(-1e3, 1e3)))
def test_magnitude_into_a_reused_array_is_bit_for_bit(rel):
    x, y = rel[:, 0], rel[:, 1]
    expected = np.sqrt(x * x + y * y)
    np.testing.assert_array_equal(segment._magnitude(rel), expected)
    reused = np.full(rel.shape[0], 7.0)
    assert segment._magnitude(rel, out=reused) is reused
    np.testing.assert_array_equal(reused, expected)
    np.testing.assert_allclose(expected, np.hypot(x, y), rtol=4e-16, atol=1e-150)  # x*x underflows


def _rotation_with_temporaries(t, rel, period):
    """segment._rotation as in the first round (each step a fresh array), for bit-for-bit checks."""

    def wrap(a):
        return a - (2 * np.pi) * np.rint(a / (2 * np.pi))

    angle = np.arctan2(rel[:, 1], rel[:, 0])
    lag = max(1, round(period / 8 / np.median(np.diff(t))))
    if angle.size <= lag + 2:
        return 0.0, 1.0
    omega0 = np.median(wrap(angle[lag:] - angle[:-lag]) / (t[lag:] - t[:-lag]))
    u = t - 0.5 * (t[0] + t[-1])
    resid = wrap(angle - omega0 * u)
    dev = wrap(resid - np.median(resid))
    good = np.abs(dev) < segment._MAX_PHASE_DEVIATION
    if np.count_nonzero(good) < 3:
        return omega0, 1.0
    slope = segment._phase_slope(u[good], dev[good], omega0)
    return omega0 + slope, 1.0 - float(np.count_nonzero(good)) / good.size


@settings(max_examples=30, deadline=None)
@given(
    omega=st.floats(-6.0, 6.0).filter(lambda w: abs(w) > 0.05),
    periods=st.floats(0.2, 12.0),
    noise=st.floats(0.0, 0.5),
    seed=st.integers(0, 2**16),
)
def test_rotation_in_place_is_bit_for_bit(omega, periods, noise, seed):
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, periods * 2 * np.pi / abs(omega), 1e-3)
    phi = omega * t + 0.3
    rel = np.column_stack([np.cos(phi), np.sin(phi)]) + noise * rng.standard_normal((t.size, 2))
    period = 2 * np.pi / abs(omega)
    assert segment._rotation(t, rel, period) == _rotation_with_temporaries(t, rel, period)


@given(
    arrays(np.float64, st.tuples(st.integers(1, 50), st.integers(1, 3)), elements=floats),
    st.data(),
)
def test_minus_row_column_by_column_is_bit_for_bit(a, data):
    row = data.draw(arrays(np.float64, a.shape[1], elements=floats))
    np.testing.assert_array_equal(segment._minus_row(a, row), a - row)
    out = np.full(a.shape, np.nan)
    assert segment._minus_row(a, row, out=out) is out
    np.testing.assert_array_equal(out, a - row)
