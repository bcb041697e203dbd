"""Designed alarms: the computed ARLs against published values, a Markov chain and Monte Carlo.

Every Monte Carlo tolerance is 3 standard errors of the simulation plus the
computation's own quadrature error (shown below 1e-6 by doubling the nodes).
"""

import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose
from scipy import special, stats

from imu_square.errors import MonitorError
from imu_square.monitor.stats.alarms import (
    AlarmDesign,
    design_alarms,
    run_charts,
    to_design_law,
)
from imu_square.monitor.stats.arl import (
    Cusum,
    Ewma,
    NightLaw,
    Shewhart,
    baseline_average,
    quadrature_error,
    solve_limit,
    solve_warning,
)
from imu_square.monitor.stats.charts import (
    ChartLimits,
    NightSampler,
    alarm_counts,
    chart_statistics,
    first_alarms,
)
from imu_square.units import URAD

# What a baseline's error does to a design is a table of the monitor benchmark.
_spec = importlib.util.spec_from_file_location(
    "benchmark_monitor", Path(__file__).parents[1] / "benchmarks" / "monitor.py"
)
_benchmark = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_benchmark)
baseline_effect = _benchmark.baseline_effect

NORMAL = NightLaw()
T14 = NightLaw(14)


def _ewma(lam, c):
    """EWMA with limit c in units of its asymptotic standard deviation (the tables' convention)."""
    return Ewma(lam, c * math.sqrt(lam / (2 - lam)))


# --- Published values ---------------------------------------------------------------------


@pytest.mark.parametrize(
    ("mu", "published"),
    [(0, 168.0), (0.25, 74.2), (0.5, 26.6), (0.75, 13.3), (1, 8.38), (1.5, 4.75), (2, 3.34),
     (2.5, 2.62), (3, 2.19), (4, 1.71), (5, 1.31)],
)  # fmt: skip
def test_two_sided_cusum_matches_lucas_crosier_1982_table_1(mu, published):
    # k = 0.5, h = 4; the table gives three significant figures.
    arl = Cusum(0.5, 4.0).arl(NORMAL.shifted(mu))
    assert float(f"{arl:.3g}") == pytest.approx(published, abs=1e-9)


def test_one_sided_cusum_matches_vance_1986_and_brook_evans_1972():
    # Vance (1986) Table 1, k = 0, h = 10 (Nystrom, 2 decimals).
    for mu, published in [(-0.125, 400.28), (0, 124.66), (0.125, 59.30), (0.25, 36.71),
                          (0.5, 20.37), (0.75, 14.06), (1, 10.75)]:  # fmt: skip
        assert round(Cusum(0.0, 10.0).one_sided_arl(NORMAL.shifted(mu)), 2) == published
    # Brook & Evans (1972) 4.3, k = 0.5, h = 3: L0 = 117.59, L1(1.5) = 3.75 (Markov chain).
    assert round(Cusum(0.5, 3.0).one_sided_arl(NORMAL), 2) == 117.60  # their chain: 117.59
    assert round(Cusum(0.5, 3.0).one_sided_arl(NORMAL.shifted(1.5)), 2) == 3.75
    # SAS/QC manual (1999), one-sided k = 0.25, h = 8, mu = 2.5: 4.1500836225.
    assert_allclose(Cusum(0.25, 8.0).one_sided_arl(NORMAL.shifted(2.5)), 4.1500836225, rtol=1e-7)


@pytest.mark.parametrize(
    ("mu", "zero_05", "zero_003", "steady_05", "steady_003"),
    [(0, 500, 500, 499, 480), (0.25, 255, 76.7, 254, 74.1), (0.5, 88.8, 29.3, 88.4, 28.6),
     (1, 17.5, 12.6, 17.3, 12.5), (2, 3.63, 5.99, 3.58, 5.95), (3, 1.93, 4.03, 1.91, 4.02),
     (5, 1.07, 2.55, 1.10, 2.55)],
)  # fmt: skip
def test_ewma_matches_lucas_saccucci_1990_table_3(mu, zero_05, zero_003, steady_05, steady_003):
    a, b = _ewma(0.5, 3.071), _ewma(0.03, 2.437)
    law = NORMAL.shifted(mu)
    assert_allclose(a.arl(law), zero_05, rtol=0.006)  # 3 significant figures
    assert_allclose(b.arl(law), zero_003, rtol=0.006)
    assert_allclose(a.steady_state_arl(law, NORMAL), steady_05, rtol=0.006)
    # Their steady state at lambda = 0.03 came from a coarse Markov chain: 1 %.
    assert_allclose(b.steady_state_arl(law, NORMAL), steady_003, rtol=0.01)


def test_ewma_matches_crowder_1987_waldmann_1986_and_sas():
    # Crowder (1987) Table 1, c = 2, 2 decimals (his 1.94 at mu = 2 is 1.9452: one in the last).
    for mu, l05, l005 in [(0, 26.45, 127.53), (0.25, 20.12, 43.94), (0.5, 11.89, 18.97),
                          (1, 4.91, 8.38), (2, 1.94, 4.04), (3, 1.26, 2.76)]:  # fmt: skip
        assert_allclose(_ewma(0.5, 2.0).arl(NORMAL.shifted(mu)), l05, atol=0.006)
        assert_allclose(_ewma(0.05, 2.0).arl(NORMAL.shifted(mu)), l005, atol=0.006)
    # Waldmann (1986) Table 1, two-sided, limit 2 in units of z: 104.0 and 1952.
    assert round(Ewma(0.75, 2.0).arl(NORMAL), 1) == 104.0
    assert round(Ewma(0.5, 2.0).arl(NORMAL)) == 1952
    # SAS/QC manual (1999): lambda 0.25, c = 3, mu = 1: 11.154267016.
    assert_allclose(_ewma(0.25, 3.0).arl(NORMAL.shifted(1.0)), 11.154267016, rtol=1e-9)


# --- The discretisation ------------------------------------------------------------------


CHARTS_AND_LAWS = [
    (Ewma(0.1, 0.84), T14),
    (Ewma(0.05, 0.5), NightLaw(3)),
    (Ewma(0.2, 1.0), NightLaw(14, 0.7)),
    (Cusum(0.5, 7.8), T14),
    (Cusum(0.07, 28.0), T14.shifted(0.14)),
    (Cusum(1.5, 8.3), NightLaw(4, -0.6)),
]


@pytest.mark.parametrize(("chart", "law"), CHARTS_AND_LAWS)
def test_doubling_the_nodes_changes_the_arl_by_less_than_1e6(chart, law):
    assert quadrature_error(chart, law) < 1e-6


def _brook_evans_cusum(k, h, m, law):
    """One-sided CUSUM by the Brook & Evans Markov chain (m states, state 0 = [0, w/2))."""
    w = 2 * h / (2 * m - 1)
    c = np.arange(m) * w
    up = law.cdf(c[None, :] + w / 2 - c[:, None] + k)
    p = up - law.cdf(c[None, :] - w / 2 - c[:, None] + k)
    p[:, 0] = up[:, 0]
    return np.linalg.solve(np.eye(m) - p, np.ones(m))[0]


def _brook_evans_ewma(lam, h, m, law):
    """Two-sided EWMA by the Markov chain of Lucas & Saccucci (m states across [-h, h])."""
    w = 2 * h / m
    c = -h + (np.arange(m) + 0.5) * w
    shift = (1 - lam) * c[:, None]
    p = law.cdf((c[None, :] + w / 2 - shift) / lam) - law.cdf((c[None, :] - w / 2 - shift) / lam)
    return np.linalg.solve(np.eye(m) - p, np.ones(m))[m // 2]


@pytest.mark.parametrize(
    ("markov", "ours"),
    [
        (lambda m: _brook_evans_cusum(0.5, 7.8, m, T14), Cusum(0.5, 7.8).one_sided_arl(T14)),
        (lambda m: _brook_evans_ewma(0.1, 0.84, m + 1, T14), Ewma(0.1, 0.84).arl(T14)),
    ],
)
def test_markov_chain_converges_to_the_integral_equation(markov, ours):
    # An independent method: the chain's error falls as 1/m^2 and, extrapolated
    # (Richardson), it meets the Nystrom value.
    l1, l2, l4 = (markov(m) for m in (100, 200, 400))
    assert abs(l4 - ours) < abs(l2 - ours) < abs(l1 - ours)
    assert_allclose((l2 - l1) / (l4 - l2), 4.0, rtol=0.1)
    assert_allclose((4 * l4 - l2) / 3, ours, rtol=2e-4)


# --- Monte Carlo ---------------------------------------------------------------------------


def _charts_for(arl0, law):
    return ChartLimits(
        solve_limit(Shewhart(1.0), arl0, law).limit,
        0.1,
        solve_limit(Ewma(0.1, 1.0), arl0, law).limit,
        0.5,
        solve_limit(Cusum(0.5, 1.0), arl0, law).limit,
    )


def _computed(limits):
    return {
        "shewhart": Shewhart(limits.shewhart),
        "ewma": Ewma(limits.ewma_lambda, limits.ewma),
        "cusum": Cusum(limits.cusum_k, limits.cusum),
    }


def _assert_mc(run_lengths, computed, label):
    rl = run_lengths[~np.isnan(run_lengths)]
    assert np.isfinite(rl).all(), label
    se = rl.std(ddof=1) / math.sqrt(rl.size)
    tolerance = 3 * se + 1e-6 * computed
    assert abs(rl.mean() - computed) < tolerance, (label, rl.mean(), se, computed)


@pytest.mark.parametrize("law", [NORMAL, T14, NightLaw(4)], ids=["normal", "t14", "t4"])
def test_in_control_arls_and_limits_agree_with_monte_carlo(law):
    limits = _charts_for(150.0, law)
    for chart in _computed(limits).values():
        assert_allclose(chart.arl(law), 150.0, rtol=1e-7)  # the solved limit hits the ARL
    rl = first_alarms(limits, NightSampler(law.nu), 8000, 3000, np.random.default_rng(11))
    for name, chart in _computed(limits).items():
        _assert_mc(rl[name], chart.arl(law), f"{name} {law}")


@pytest.mark.parametrize("law", [NORMAL, T14], ids=["normal", "t14"])
@pytest.mark.parametrize("shift", [0.5, -1.0, 2.0])
def test_out_of_control_arls_agree_with_monte_carlo(law, shift):
    limits = _charts_for(300.0, law)
    after = law.shifted(shift)
    sampler = NightSampler(law.nu, shift)
    rl = first_alarms(limits, sampler, 6000, 3000, np.random.default_rng(12))
    for name, chart in _computed(limits).items():
        _assert_mc(rl[name], chart.arl(after), f"zero-state {name} {shift}")
    # Steady state: 100 quiet nights, then the step.
    mean = np.concatenate([np.zeros(100), [shift]])
    rl = first_alarms(
        limits, NightSampler(law.nu, mean), 6000, 3000, np.random.default_rng(13), burn_in=100
    )
    for name, chart in _computed(limits).items():
        _assert_mc(rl[name], chart.steady_state_arl(after, law), f"steady {name} {shift}")


def test_two_sided_cusum_formula_holds_where_both_halves_can_be_high():
    # k = 0.25 leaves both halves above zero together often; the formula still holds.
    chart, law = Cusum(0.25, 5.0), T14.shifted(0.3)
    limits = ChartLimits(math.inf, 0.1, math.inf, chart.k, chart.limit)
    rl = first_alarms(
        limits, NightSampler(14, 0.3), 8000, 2000, np.random.default_rng(14), per_chart=False
    )
    _assert_mc(rl["combined"], chart.arl(law), "two-sided cusum")


def test_warning_occupancy_agrees_with_monte_carlo():
    limits = _charts_for(400.0, T14)
    charts = _computed(limits)
    warn = {name: solve_warning(c, 0.01, T14) for name, c in charts.items()}
    for name, w in warn.items():
        assert w < charts[name].limit
        assert_allclose(charts[name].occupancy(T14)(w), 0.01, rtol=1e-7)
    # Each chart alone, restarted after its alarms: fraction of nights past its warning limit.
    for name in charts:

        def alone(values, name=name):
            return ChartLimits(
                values["shewhart"] if name == "shewhart" else math.inf,
                0.1,
                values["ewma"] if name == "ewma" else math.inf,
                0.5,
                values["cusum"] if name == "cusum" else math.inf,
            )

        only = alone({"shewhart": limits.shewhart, "ewma": limits.ewma, "cusum": limits.cusum})
        wl = alone(warn)
        c = alarm_counts(only, wl, NightSampler(14), 400, 2000, np.random.default_rng(15))
        per_path = c["warning_nights"] / c["n_nights"]
        se = per_path.std(ddof=1) / math.sqrt(per_path.size)
        # The renewal's fresh starts after alarms sit below the warning limit: a bias down of
        # about the nights after a restart before the quasi-stationary state (a few per alarm).
        assert abs(per_path.mean() - 0.01) < 3 * se + 0.0005, (name, per_path.mean(), se)


def test_baseline_average_agrees_with_monte_carlo_and_converges():
    rho, law = 0.3, NORMAL
    chart = Cusum(0.8, 6.0)
    avg = baseline_average(chart, law, rho)
    fine = baseline_average(chart, law, rho, nodes=48)
    assert_allclose(avg["rate_arl"], fine["rate_arl"], rtol=1e-3)
    # The p10 baseline: exactly the ARL at the 90th percentile of |e|.
    assert_allclose(avg["p10_arl"], chart.arl(law.shifted(special.ndtri(0.95) * rho)))
    # One over the mean rate <= the mean ARL <= the ARL of an exact baseline.
    assert avg["p10_arl"] < avg["rate_arl"] < avg["mean_arl"] < chart.arl(law)
    offsets = rho * np.random.default_rng(16).standard_normal(3000)
    limits = ChartLimits(math.inf, 0.1, math.inf, chart.k, chart.limit)
    c = alarm_counts(limits, None, NightSampler(None, 0.0, offsets), 3000, 1500,
                     np.random.default_rng(17))  # fmt: skip
    per_path = c["alarms"] / c["n_nights"]
    se = per_path.std(ddof=1) / math.sqrt(per_path.size)
    assert abs(per_path.mean() - 1 / avg["rate_arl"]) < 3 * se


def test_a_chart_no_baseline_can_fire_averages_to_an_infinite_arl_without_a_warning():
    # a limit of 60 sigmas: no baseline within 6 rho fires to double precision (a night's
    # diagnostic whose uncertainty is tiny against its alarm's step); a divide by zero
    # used to surface as "imu-square: warning: divide by zero" in the nightly run
    import warnings

    chart = Shewhart(60.0)
    assert chart.arl(NORMAL.shifted(6 * 0.3)) == math.inf
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        avg = baseline_average(chart, NORMAL, 0.3)
    assert avg["rate_arl"] == avg["mean_arl"] == math.inf


def test_solved_limits_meet_the_baseline_averaged_rate_under_t():
    for chart in (Shewhart(1.0), Cusum(1.2, 1.0)):
        solved = solve_limit(chart, 500.0, T14, baseline_sd=0.3)
        assert_allclose(baseline_average(solved, T14, 0.3)["rate_arl"], 500.0, rtol=1e-6)
        assert solved.limit > solve_limit(chart, 500.0, T14).limit


@settings(max_examples=25, deadline=None)
@given(
    h=st.floats(0.5, 12.0),
    dh=st.floats(0.05, 3.0),
    k=st.floats(0.0, 1.5),
    mu=st.floats(-2.0, 2.0),
)
def test_cusum_arl_rises_with_h_and_falls_with_the_shift(h, dh, k, mu):
    law = NightLaw(10, mu)
    assert Cusum(k, h + dh).arl(law) > Cusum(k, h).arl(law)
    assert Cusum(k, h).arl(law.shifted(math.copysign(0.3, mu))) < Cusum(k, h).arl(law)


@settings(max_examples=25, deadline=None)
@given(c=st.floats(1.0, 3.5), dc=st.floats(0.05, 0.5), lam=st.floats(0.05, 1.0))
def test_ewma_arl_rises_with_the_limit(c, dc, lam):
    # limits in units of the statistic's stationary sd, so the ARLs stay finite
    # (past about 4.5 sd they overflow double precision for a small lambda)
    sd = math.sqrt(lam / (2.0 - lam))
    low, high = Ewma(lam, c * sd).arl(T14), Ewma(lam, (c + dc) * sd).arl(T14)
    assert math.isfinite(high) and high > low


@settings(max_examples=30, deadline=None)
@given(
    z=st.lists(st.floats(-6, 6), min_size=1, max_size=40),
    lam=st.floats(0.01, 1.0),
    k=st.floats(0.0, 2.0),
    start=st.tuples(st.floats(-2, 2), st.floats(0, 5), st.floats(0, 5)),
)
def test_vectorised_statistics_equal_the_plain_recursion(z, lam, k, start):
    ewma, cpos, cneg = chart_statistics(np.array(z), lam, k, [np.array(s) for s in start])
    e, p, n = start
    for i, zi in enumerate(z):
        e = (1 - lam) * e + lam * zi
        p = max(0.0, p + zi - k)
        n = max(0.0, n - zi - k)
        assert_allclose([ewma[i], cpos[i], cneg[i]], [e, p, n], atol=1e-9)


def test_renewal_simulation_equals_a_plain_loop():
    # Same random numbers (same blocks), counted night by night with restarts.
    limits = ChartLimits(2.8, 0.2, 0.7, 0.5, 3.0)
    warnings = ChartLimits(2.0, 0.2, 0.45, 0.5, 1.8)
    sampler = NightSampler(6)
    c = alarm_counts(limits, warnings, sampler, 7, 600, np.random.default_rng(18), block=64)
    rng = np.random.default_rng(18)
    blocks = [sampler.draw(rng, np.arange(7), f, min(64, 600 - f)) for f in range(0, 600, 64)]
    z = np.concatenate(blocks, axis=1)
    for p in range(7):
        e = cp = cn = 0.0
        alarms = warned = onsets = 0
        prev = False
        for zi in z[p]:
            e, cp, cn = 0.8 * e + 0.2 * zi, max(0.0, cp + zi - 0.5), max(0.0, cn - zi - 0.5)
            if abs(zi) > 2.8 or abs(e) > 0.7 or max(cp, cn) > 3.0:
                alarms += 1
                e = cp = cn = 0.0
                prev = False
                continue
            now = abs(zi) > 2.0 or abs(e) > 0.45 or max(cp, cn) > 1.8
            warned += now
            onsets += now and not prev
            prev = now
        assert (c["alarms"][p], c["warning_nights"][p], c["warning_onsets"][p]) == (
            alarms,
            warned,
            onsets,
        )
    assert c["alarms"].sum() > 10  # the restarts were exercised


# --- The design ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def design():
    # The fast test of a small-sigma program: 10 µm/m is 2.5 sigma.
    return design_alarms(730, 4 * URAD, nu=None, mc_nights=2_000_000, seed=3)


def test_design_meets_the_asked_false_alarm_rate_combined(design):
    c = design.check
    assert c.n_paths * c.n_nights > 0.99 * 2_000_000
    # Each chart on its share, scaled by the measured overlap of the three.
    for chart in design.charts:
        assert_allclose(chart.arl0, 730 * 3 / design.overlap, rtol=1e-6)
        assert chart.quadrature_error < 1e-6
    assert 1.0 < design.overlap < 2.0
    # An independent Monte Carlo of the combined scheme, with its own seed.
    counts = alarm_counts(
        design.limits, design.warnings, NightSampler(None), 1000, 2000, np.random.default_rng(19)
    )
    per_path = counts["alarms"] / counts["n_nights"]
    se = per_path.std(ddof=1) / math.sqrt(per_path.size)
    rate = per_path.mean()
    # The design's overlap came from a simulation of the same size: both errors count.
    u_design = design.check.u_arl0 / 730**2
    assert abs(rate - 1 / 730) < 3 * math.hypot(se, u_design), (1 / rate, c.arl0)
    assert abs(c.arl0 - 730) < 3 * math.hypot(c.u_arl0, se / rate**2)
    # Warnings: the asked 2 % of nights.
    warn = counts["warning_nights"] / counts["n_nights"]
    assert abs(warn.mean() - 0.02) < 3 * math.hypot(warn.std(ddof=1) / math.sqrt(1000), 2e-4)
    for chart in design.charts:
        assert chart.warning_limit < chart.limit


def test_design_reports_out_of_control_run_lengths(design):
    delta = design.step_sd
    assert_allclose(delta, 2.5)
    assert design.cusum.parameter == pytest.approx(1.25)  # half the named step
    law = NightLaw(None, delta)
    assert_allclose(design.cusum.arl1, Cusum(1.25, design.cusum.limit).arl(law))
    # The scheme finds the step sooner than any chart alone, and the ramp later than the step.
    c = design.check
    assert c.arl1 <= min(ch.arl1 for ch in design.charts) + 3 * c.u_arl1
    assert c.arl1_steady <= c.arl1 + 3 * math.hypot(c.u_arl1, c.u_arl1_steady)
    assert c.arl1 < c.ramp_median <= c.ramp_p90 < 90
    assert c.step_median <= c.arl1 + 3 * c.u_arl1 and c.step_median <= c.step_p90


def test_design_round_trips_through_json_and_describes_itself(design):
    data = json.loads(json.dumps(design.to_json_dict(), allow_nan=False))
    again = AlarmDesign.from_json_dict(data)
    assert again.limits == design.limits
    assert again.warnings == design.warnings
    assert again.charts == design.charts
    assert again.check == design.check
    assert_allclose(again.sigma_rad, design.sigma_rad, rtol=1e-15)
    assert data["check"]["false_alarms_per_year"] == pytest.approx(365.25 / design.check.arl0)
    text = design.describe()
    assert f"{design.shewhart.limit:.2f}" in text and f"{design.cusum.limit:.2f}" in text
    assert "730 valid nights" in text
    with pytest.raises(MonitorError, match=r"alarm design: the field 'cusum' is missing"):
        AlarmDesign.from_json_dict({k: v for k, v in data.items() if k != "cusum"})


def test_t_law_needs_wider_limits_than_the_normal():
    # Designed on the normal, nights with 14 degrees of freedom alarm far more often.
    normal = solve_limit(Shewhart(1.0), 730, NORMAL)
    assert 1 / normal.arl(T14) / (1 / 730) > 2.5
    assert solve_limit(Shewhart(1.0), 730, T14).limit > normal.limit + 0.75


def test_baseline_error_shortens_the_false_alarm_runs_of_an_exact_baseline_design(design):
    rows = baseline_effect(design, [1 / math.sqrt(n) for n in (3, 20)])
    for row in rows:
        for name in ("shewhart", "ewma", "cusum"):
            assert row[name]["rate_arl"] < getattr(design, name).arl0
    # The EWMA and the CUSUM add the common error up: hit far harder than the Shewhart.
    n20 = rows[1]
    assert n20["ewma"]["rate_arl"] < 0.5 * n20["shewhart"]["rate_arl"]


def test_cusum_k_is_not_tuned_below_the_baseline_error():
    # sigma 8 µm/m: half the step (0.625 sigma) is below 2.576 / sqrt(5) = 1.15.
    d = design_alarms(200, 8 * URAD, baseline_sd_ratio=1 / math.sqrt(5), mc_nights=200_000)
    assert d.cusum.parameter == pytest.approx(2.5758293035489 / math.sqrt(5))
    for chart in d.charts:  # rate-averaged over the baseline's error
        assert_allclose(chart.arl0, 200 * 3 / d.overlap, rtol=1e-5)
    # The overlap was measured by a simulation as large as the check's: both errors count.
    assert abs(d.check.arl0 - 200) < 3 * math.sqrt(2) * d.check.u_arl0


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"arl0_nights": 5}, r"arl0_nights must be a number within \[10, inf\] nights, got 5"),
        ({"sigma_rad": 0.0}, r"sigma_rad must be a number within \(0, inf\] rad, got 0.0"),
        ({"sigma_rad": math.nan}, r"sigma_rad must be a number"),
        ({"nu": 0.5}, r"nu must be None \(normal\) or a number >= 1, got 0.5"),
        ({"baseline_sd_ratio": -0.1}, r"baseline_sd_ratio must be a number within \[0, 2\]"),
        ({"ewma_lambda": 1.5}, r"ewma_lambda must be a number within \(0, 1\]"),
        ({"shares": (0.5, 0.5, 0.0)}, r"shares must be 3 numbers > 0 summing to 1"),
        ({"warning_fraction": 0.0}, r"warning_fraction must be a number within \(0, 0.5\]"),
        ({"cusum_k": -1.0}, r"cusum_k must be a number within \[0, inf\]"),
        ({"ramp_nights": 0}, r"ramp_nights must be an integer >= 1, got 0"),
        ({"mc_nights": 10}, r"mc_nights must be an integer >= 100000, got 10"),
    ],
)
def test_design_refuses_bad_parameters(kwargs, message):
    args = {"arl0_nights": 730, "sigma_rad": 4 * URAD} | kwargs
    with pytest.raises(MonitorError, match=message):
        design_alarms(args.pop("arl0_nights"), args.pop("sigma_rad"), **args)


# A bool is no number here either (imu_square.validation), as in every file: True
# was taken as 1.0 (ewma_lambda, cusum_k) and as one degree of freedom (nu).
@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"ewma_lambda": True}, r"^ewma_lambda must be a number within \(0, 1\], got True$"),
        ({"cusum_k": True}, r"^cusum_k must be a number within \[0, inf\], got True$"),
        ({"nu": True}, r"^nu must be None \(normal\) or a number >= 1, got True$"),
    ],
)
def test_design_refuses_a_bool_for_a_number(kwargs, message):
    test_design_refuses_bad_parameters(kwargs, message)


def test_evaluation_refuses_a_bool_for_the_degrees_of_freedom(design):
    with pytest.raises(MonitorError, match=r"^nu of night 0 must be None \(normal\) or a number"):
        run_charts(design, [1e-6], [1e-6], [True])


# --- ChartRun -----------------------------------------------------------------------------


def test_evaluation_fires_on_the_expected_nights(design):
    u = 4 * URAD
    sh, ew, cu = design.shewhart, design.ewma, design.cusum
    k, h = cu.parameter, cu.limit
    # A drift the Shewhart never sees: z = k + 0.3 each night, so C+ grows 0.3 a night.
    level = k + 0.3
    assert level < sh.warning_limit
    lam = ew.parameter
    first_cusum = math.floor(h / 0.3) + 1  # nights until C+ > h
    first_ewma = math.floor(math.log(1 - ew.limit / level) / math.log(1 - lam)) + 1
    expected = min(first_cusum, first_ewma)
    nights = np.full(40, level * u)
    ev = run_charts(design, nights, np.full(40, u), nu=None)
    alarm_nights = ev.alarm_nights
    assert alarm_nights[0] == expected - 1  # night indices start at 0
    which = ev.points[expected - 1].alarms
    assert ("cusum" in which) == (first_cusum == expected)
    assert ("ewma" in which) == (first_ewma == expected)
    assert ev.points[expected - 1].direction == 1
    # After the alarm the charts restart from zero, so the drift fires again as late.
    assert alarm_nights[1] - alarm_nights[0] == expected
    assert ev.points[expected].cusum_pos == pytest.approx(0.3)
    # Before the alarm, a warning once a statistic passes its warning limit.
    states = [p.state for p in ev.points[: expected - 1]]
    assert states[0] == "ok" and "warning" in states and "alarm" not in states


def test_evaluation_of_a_single_jump_and_the_t_mapping(design):
    u = 4 * URAD
    change = np.zeros(10)
    change[6] = -1.01 * design.shewhart.limit * u
    ev = run_charts(design, change, np.full(10, u))
    assert ev.alarm_nights == (6,)
    assert ev.points[6].alarms[0] == "shewhart" and ev.points[6].direction == -1
    assert ev.points[7].ewma == 0.0 and ev.points[7].cusum_neg == 0.0  # restarted
    assert ev.state == "ok"
    # A night with 4 degrees of freedom: its z is mapped onto the design's normal law.
    ev = run_charts(design, [3 * u], [u], nu=4)
    assert_allclose(ev.points[0].z, stats.norm.isf(stats.t.sf(3, 4)), rtol=1e-12)
    assert ev.points[0].z < 2.6
    # A night with the design's law is charted as it is.
    assert run_charts(design, [3 * u], [u], nu=[None]).points[0].z == pytest.approx(3.0)
    assert run_charts(design, [], []).state == "ok"
    assert json.dumps(ev.to_json_dict(), allow_nan=False)


def test_evaluation_matches_the_vectorised_statistics_when_quiet(design):
    z = np.random.default_rng(20).normal(0, 0.5, 60)
    ev = run_charts(design, z * URAD, np.full(60, URAD))
    assert not ev.alarm_nights
    ewma, cpos, cneg = chart_statistics(z, design.ewma.parameter, design.cusum.parameter)
    assert_allclose([p.ewma for p in ev.points], ewma, atol=1e-12)
    assert_allclose([p.cusum_pos for p in ev.points], cpos, atol=1e-12)
    assert_allclose([p.cusum_neg for p in ev.points], cneg, atol=1e-12)


def test_mapping_onto_the_design_law_keeps_each_nights_tail_probability():
    z = np.array([-7.0, -2.5, -0.3, 0.0, 0.4, 1.9, 3.3, 60.0])
    nu = np.array([4.0, np.nan, 14.0, 4.0, 30.0, np.nan, 4.0, 2.0])
    mapped = to_design_law(z, nu, 14.0)
    own = np.where(np.isnan(nu), stats.norm.cdf(z), stats.t.cdf(z, np.nan_to_num(nu, nan=1.0)))
    assert_allclose(stats.t.cdf(mapped, 14), own, rtol=1e-10, atol=1e-300)
    assert mapped[2] == z[2]  # the design's own law: unchanged
    assert abs(mapped[0]) < 7.0 and abs(mapped[5]) > 1.9  # t(4) tails pulled in, normal pushed out
    assert_allclose(to_design_law(z, None, None), z)
    # A normal tail beyond double precision (sf(40) underflows) keeps the night's own z.
    assert to_design_law([-40.0], None, 3.0)[0] == -40.0
    assert to_design_law([1e4], 2.0, None)[0] == pytest.approx(stats.norm.isf(stats.t.sf(1e4, 2)))


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (([1e-6, 2e-6], [1e-6]), r"change_rad and u_change_rad must have the same length, got 2 "),
        (([1e-6, math.nan], [1e-6, 1e-6]), r"change_rad must be finite, got nan on night 1"),
        (([1e-6], [0.0]), r"u_change_rad must be finite and > 0, got 0.0 on night 0"),
        (([1e-6], [-math.inf]), r"u_change_rad must be finite and > 0, got -inf on night 0"),
        (([1e-6], [1e-6], [0.2]), r"nu of night 0 must be None \(normal\) or a number >= 1, got 0"),
        (([1e-6], [1e-6], [3, 4]), r"nu must be one value or one per night \(1\), got 2"),
    ],
)  # fmt: skip
def test_evaluation_refuses_bad_nights(design, args, message):
    with pytest.raises(MonitorError, match=message):
        run_charts(design, *args)


def test_far_shifts_and_poor_baselines_stay_finite():
    # scipy's noncentral t gives NaN where a tail underflows: the law must not pass it on.
    law = NightLaw(nu=19)
    tails = [law.shifted(d).tail(4.0) for d in np.linspace(0.0, 12.0, 25)]
    assert all(np.isfinite(tails)) and np.all(np.diff(tails) > 0) and tails[-1] <= 1.0
    assert law.shifted(-8.0).tail(4.0) == pytest.approx(law.shifted(8.0).tail(4.0), rel=1e-12)
    assert np.all(np.isfinite(law.shifted(6.0).cdf(np.array([-4.0, 0.0, 6.0]))))
    # a baseline from three noisy runs is as poor as 0.7-1.5 nights' sigma: still designed
    for ratio in (0.7, 1.5):
        d = design_alarms(
            730, 17e-6, step_rad=30e-6, nu=19, baseline_sd_ratio=ratio, mc_nights=200_000
        )
        assert all(np.isfinite([c.limit for c in d.charts])) and d.check.arl0 > 300


def test_a_cusum_that_rests_at_zero_warns_as_soon_as_it_leaves_it():
    # k = 2.2: C+ or C- is above zero on 4.8 % of t14 nights, so no limit above zero
    # gives the 5 % asked; the warning is then any night off zero
    chart = Cusum(2.2, 10.0)
    assert 0.04 < chart.occupancy(T14)(0.0) < 0.05
    assert solve_warning(chart, 0.05, T14) == 0.0
    w = solve_warning(chart, 0.01, T14)
    assert 0.0 < w < chart.limit
    assert_allclose(chart.occupancy(T14)(w), 0.01, rtol=1e-7)
