"""Newton's solver of the bootstrap against IRLS, the reference it replaces."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from imu_square.io.mcap import read_mcap, write_mcap
from imu_square.pipeline import per_cycle
from imu_square.pipeline import squareness as sq
from imu_square.pipeline.newton import _positive_definite, first_order_params, fit_newton
from imu_square.pipeline.options import AnalysisOptions
from imu_square.pipeline.sine_fit import (
    circle_phases,
    fit_circle,
    fit_irls,
    robust_norm,
    sine_design,
)
from imu_square.pipeline.stage2 import fit_cross_terms
from imu_square.pipeline.uncertainty import bootstrap_counts
from imu_square.program import read_program
from imu_square.simulate import data_path, read_machine, read_sensor, simulate_run

PHI = 2 * np.pi * (np.arange(512) + 0.5) / 512
EXOG = sine_design(PHI)
IRLS = {"maxiter": 200, "tol": 1e-10, "conv": "coefs", "freeze_scale_after": 50}
TUKEY = robust_norm("tukey")


def _resampled_means(seed=0, n_cycles=15, n_boot=64, noise=2e-3, spike=0.02):
    """Means of resampled spiky cycles, as the bootstrap makes them, and the full mean's fit."""
    rng = np.random.default_rng(seed)
    clean = 0.003 - 0.1 * np.cos(PHI - 2e-4)
    bump = spike * (np.exp(-((np.angle(np.exp(1j * PHI)) / 0.05) ** 2)))  # a reversal spike
    cycles = clean + bump + rng.normal(0, noise, (n_cycles, PHI.size))
    draws = bootstrap_counts(n_cycles, n_boot, rng)
    start = fit_irls(EXOG, cycles.mean(axis=0), TUKEY, **IRLS).params[0]
    return draws @ cycles / n_cycles, start


def test_newton_reaches_the_irls_estimate():
    rows, start = _resampled_means()
    ours, handed = fit_newton(EXOG, rows, start, TUKEY, **IRLS)
    ref = fit_irls(EXOG, rows, TUKEY, start_params=start, **IRLS)
    assert ref.converged.all() and handed == 0
    # Both stop when a step moves every coefficient less than 1e-10 m/s^2.
    assert_allclose(ours, ref.params, rtol=0, atol=1e-9)
    assert ref.iterations.mean() > 5  # the case that Newton is for: spiky, slow for IRLS


def test_newton_with_missing_points_matches_irls():
    rows, start = _resampled_means(seed=1)
    prior = np.ones_like(rows)
    prior[:, 100:140] = 0.0  # a bridged gap: no data there
    prior[::3, 300:310] = 0.5
    rows[:, 100:140] = np.nan  # never read
    ours, handed = fit_newton(EXOG, rows, start, TUKEY, prior_weights=prior, **IRLS)
    ref = fit_irls(EXOG, rows, TUKEY, start_params=start, prior_weights=prior, **IRLS)
    assert handed == 0
    assert_allclose(ours, ref.params, rtol=0, atol=1e-9)


def test_rows_newton_cannot_take_are_handed_to_irls():
    rows, start = _resampled_means(seed=2, n_boot=8)
    # Row 0: residuals 6x larger where |cos(phi)| > 0.75 (46 % of the points) than elsewhere,
    # which puts them at 4 robust sd, where Tukey's psi' < 0 (beyond c / sqrt(5) = 2.1):
    # the Hessian is indefinite along the cos coefficient.
    z = np.where(np.abs(np.cos(PHI)) > 0.75, 3.0, 0.5) * np.where(np.arange(PHI.size) % 2, 1, -1)
    rows[0] = EXOG @ start + 1e-3 * z
    ours, handed = fit_newton(EXOG, rows, start, TUKEY, **IRLS)
    assert handed == 1
    ref = fit_irls(EXOG, rows[:1], TUKEY, start_params=start, **IRLS)
    assert_allclose(ours[0], ref.params[0], rtol=0, atol=0)
    assert_allclose(
        ours[1:],
        fit_irls(EXOG, rows[1:], TUKEY, start_params=start, **IRLS).params,
        rtol=0,
        atol=1e-9,
    )
    _, all_handed = fit_newton(EXOG, rows, start, TUKEY, **{**IRLS, "conv": "dev"})
    assert all_handed == 8  # "dev" is IRLS's own criterion


def test_an_exact_fit_stays_put():
    exact = (0.003 - 0.1 * np.cos(PHI - 2e-4))[None]
    start = fit_irls(EXOG, exact[0], TUKEY, **IRLS).params[0]
    ours, handed = fit_newton(EXOG, exact, start, TUKEY, **IRLS)
    assert handed == 0
    theta, _ = circle_phases(ours, ours)
    assert theta[0] == pytest.approx(2e-4, abs=1e-12)


@pytest.fixture(scope="module")
def typical_run(tmp_path_factory):
    """A typical machine's run (reversal spikes, backlash, vibration), through MCAP."""
    rec, _ = simulate_run(
        read_program(data_path("program_paper.toml")),
        read_machine(data_path("machine_typical.toml")),
        read_sensor(data_path("sensor_paper.toml")),
        seed=5,
    )
    path = tmp_path_factory.mktemp("typical") / "run.mcap"
    write_mcap(rec, path)
    return read_mcap(path)


def test_bootstrap_spread_is_the_irls_one(typical_run, monkeypatch):
    """The bootstrap's u within a thousandth of the all-IRLS bootstrap's, on the same draws."""
    seen = {}
    fit_cycles = per_cycle.fit_cycles

    def keep(cycles, mean_fit, *args):
        seen["cycles"], seen["mean"] = cycles, mean_fit
        return fit_cycles(cycles, mean_fit, *args)

    monkeypatch.setattr(sq, "fit_cycles", keep)
    opts = AnalysisOptions()
    result = sq.analyze(typical_run, opts)
    cycles, main = seen["cycles"], seen["mean"].fit
    rng = np.random.default_rng(opts.seed)
    boot = []
    for i, c in enumerate((cycles.ccw, cycles.cw)):
        draws = bootstrap_counts(c.n, opts.bootstrap_n, rng)
        means = [draws @ v / c.n for v in (c.x, c.y)]
        start = (main.x.params[i], main.y.params[i])
        ref = fit_circle(cycles.phi_grid, *means, opts.robust_norm(), start, **opts.irls())
        assert np.mean(np.minimum(ref.x.iterations, ref.y.iterations)) > 5
        boot.append(ref.squareness)
    reference = np.std(0.5 * (boot[0] + boot[1]), ddof=1)
    assert result.u_squareness_bootstrap_rad == pytest.approx(reference, rel=1e-3)
    assert result.quality["warnings"]  # the spikes are there: the fits reject points


def test_stage_two_by_newton_is_the_irls_fit():
    rng = np.random.default_rng(3)
    a_x = 0.002 - 0.1 * np.cos(PHI - 3e-4) + rng.normal(0, 1e-3, PHI.size)
    a_y = -0.1 * np.sin(PHI + 1e-4) + rng.normal(0, 1e-3, PHI.size)
    a_x[::50] += 0.05  # spikes, which the robust fits reject
    a_y[25::50] -= 0.05
    # A least-squares stage 1 takes the spikes in; the robust stage 2 then has work to do.
    s1 = fit_circle(PHI, a_x, a_y, robust_norm("ols"), **IRLS)
    ours = fit_cross_terms(PHI, s1, TUKEY, **IRLS)
    ex = np.column_stack([np.ones_like(PHI), np.cos(PHI + np.pi / 2 - s1.theta_y[0])])
    ey = np.column_stack([np.ones_like(PHI), np.cos(PHI - s1.theta_x[0])])
    ref_y = fit_irls(ex, s1.x.resid[0], TUKEY, **IRLS).params[0, 1]  # from OLS, as statsmodels
    ref_x = fit_irls(ey, s1.y.resid[0], TUKEY, **IRLS).params[0, 1]
    assert abs(ours.c_y[0] - ref_y) < 1e-9 and abs(ours.c_x[0] - ref_x) < 1e-9
    assert min(abs(ref_y), abs(ref_x)) > 1e-7  # not two zeros agreeing


@settings(max_examples=200, deadline=None)
@given(
    st.integers(1, 5),
    st.integers(0, 2**32 - 1),
    st.floats(-1.0, 1.0),
)
def test_positive_definite_is_numpys(p, seed, shift):
    rng = np.random.default_rng(seed)
    m = rng.normal(size=(64, p, p))
    sym = m @ m.transpose(0, 2, 1) / p + shift * np.eye(p)  # about half of them indefinite
    expected = np.linalg.eigvalsh(sym)[:, 0] > 0
    assert np.array_equal(_positive_definite(sym), expected)


def test_first_order_start_is_near_the_resamples_estimate():
    rng = np.random.default_rng(4)
    clean = 0.003 - 0.1 * np.cos(PHI - 2e-4)
    bump = 0.02 * np.exp(-((np.angle(np.exp(1j * PHI)) / 0.05) ** 2))
    cycles = clean + bump + rng.normal(0, 2e-3, (15, PHI.size))
    mean = cycles.mean(axis=0)
    fit = fit_irls(EXOG, mean, TUKEY, **IRLS)
    rows = bootstrap_counts(15, 64, rng) @ cycles / 15
    exact, _ = fit_newton(EXOG, rows, fit.params[0], TUKEY, **IRLS)
    start = first_order_params(EXOG, fit, 0, TUKEY, rows - mean)
    moved = np.abs(exact - fit.params[0]).max(axis=-1)
    missed = np.abs(exact - start).max(axis=-1)
    # First order, the scale held: most of the way, for nearly every resample (0.27 here).
    assert np.median(missed / moved) < 0.4
    assert np.mean(missed < moved) > 0.9
    assert np.median(moved) > 1e-5  # resampling moved the fits by many tolerances


@pytest.mark.parametrize("shape", ["(n_obs,)", "(1, n_obs)"])
def test_prior_weights_shared_by_all_rows_as_in_irls(shape):
    """One row of prior weights for every fit, as fit_irls takes it (a mean trace's gaps)."""
    rows, start = _resampled_means(seed=6, n_boot=16)
    rows[0] = EXOG @ start + np.random.default_rng(6).normal(0, 2e-5, PHI.size)  # converges first
    prior = np.ones(PHI.size)
    prior[100:140] = 0.0
    prior[300:310] = 0.5
    rows[:, 100:140] = np.nan  # never read
    shared = prior if shape == "(n_obs,)" else prior[None]
    ours, handed = fit_newton(EXOG, rows, start, TUKEY, prior_weights=shared, **IRLS)
    ref = fit_irls(EXOG, rows, TUKEY, start_params=start, prior_weights=shared, **IRLS)
    assert handed == 0
    assert_allclose(ours, ref.params, rtol=0, atol=1e-9)
