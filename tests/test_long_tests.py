"""A test of hundreds of cycles: the charts' laws stay finite, and the machine gets a baseline.

A fast circle run for minutes gives a night's type A uncertainty hundreds of
degrees of freedom. scipy's noncentral t density overflows there (its gamma
function) or gives NaN where the night and the shift differ in sign; the
monitor's own density must not.
"""

import math
import warnings

import monitor_rig as rig
import numpy as np
import pytest
from scipy import stats

from imu_square.cli import main
from imu_square.monitor.history.store import open_history
from imu_square.monitor.stats.alarms import design_alarms
from imu_square.monitor.stats.arl import NightLaw, noncentral_t_pdf
from imu_square.program import program_from_mapping
from imu_square.simulate.sensor import SensorModel
from imu_square.units import URAD


@pytest.mark.parametrize("nu", [1, 2, 5, 30, 199, 471, 5000])
@pytest.mark.parametrize("shift", [-15.0, -3.0, 0.5, 6.0])
def test_the_density_is_scipys_wherever_scipys_is_finite(nu, shift):
    x = np.concatenate([-np.geomspace(1e-3, 300, 200)[::-1], [0.0], np.geomspace(1e-3, 300, 200)])
    ours = noncentral_t_pdf(x, nu, shift)
    assert np.all(np.isfinite(ours)) and np.all(ours >= 0.0)
    reference = np.full_like(x, np.nan)
    for i, xi in enumerate(x):  # scipy raises for a whole array once one point overflows
        try:
            with warnings.catch_warnings():  # boost warns where its quadrature gives up
                warnings.simplefilter("ignore", RuntimeWarning)
                reference[i] = stats.nct.pdf(xi, nu, shift)
        except OverflowError:
            pass
    known = np.isfinite(reference)
    assert known.sum() > 100
    np.testing.assert_allclose(ours[known], reference[known], rtol=0, atol=1e-10 * ours.max())


def test_the_density_integrates_to_one_where_scipy_overflows():
    # The case: scipy raises for nu = 471 on this grid.
    with pytest.raises(OverflowError), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        stats.nct.pdf(np.sinh(np.linspace(-8, 8, 50)) * 2, 471, 1.3)
    x = np.linspace(-40.0, 40.0, 80001)
    for nu in (471, 5000, 10**6):
        density = NightLaw(nu=nu, shift=1.3).pdf(x)  # the spline: 1e-8 of the peak
        assert np.trapezoid(density, x) == pytest.approx(1.0, abs=1e-8)
        mean = np.trapezoid(x * density, x)
        # E[T] = shift sqrt(nu/2) Gamma((nu-1)/2) / Gamma(nu/2)
        exact = 1.3 * math.sqrt(nu / 2) * math.exp(math.lgamma((nu - 1) / 2) - math.lgamma(nu / 2))
        assert mean == pytest.approx(exact, rel=1e-8)


def test_a_design_for_hundreds_of_degrees_of_freedom_approaches_the_normal_one():
    common = dict(step_rad=10 * URAD, baseline_sd_ratio=0.3, mc_nights=200_000)
    long = design_alarms(730, 2 * URAD, nu=471, **common)
    normal = design_alarms(730, 2 * URAD, nu=None, **common)
    short = design_alarms(730, 2 * URAD, nu=19, **common)
    for a, b, c in zip(long.charts, normal.charts, short.charts, strict=True):
        # Student's t at 471 dof moves the limits by a few per cent from the normal's
        # (t's tails are heavier by about (z^4 + 2 z^2) / (4 nu)); at 19 dof by more.
        assert a.limit == pytest.approx(b.limit, rel=0.05)
        assert abs(c.limit - b.limit) > abs(a.limit - b.limit)


@pytest.mark.slow
def test_baseline_set_on_a_test_of_hundreds_of_cycles_gives_a_baseline(tmp_path, monkeypatch):
    # The planner's fast test for a 1 g machine: r = 25 mm at 30 m/min, 3.2 Hz circles,
    # here 300 cycles each way (nu = 299), sampled at 200 Hz to keep the test short.
    program = program_from_mapping(
        {"radius_mm": 25.0, "feed_mm_per_min": 30000.0, "cycles_per_direction": 300, "dwell_s": 1.0}
    )
    sensor = SensorModel(
        sample_rate_hz=200.0, noise_density_m_s2_rthz=25e-6 * 9.80665, eps_c_rad=math.radians(2.1)
    )
    monkeypatch.setattr(rig, "PROGRAM", program)
    folder = rig.make_base(tmp_path, nights=3, sensor=sensor)
    with open_history(folder / "history.db") as history:
        baseline = history.current_baseline("m1")
    assert baseline is not None and baseline.alarm_design
    assert (
        main(
            [
                "nightly",
                "--config",
                str(folder / "monitor.toml"),
                "--recording",
                str(rig.night(folder, 10, sensor=sensor)),
            ]
        )
        == 0
    )


def test_a_step_of_many_sigmas_gets_a_design_not_a_hang():
    # A named step of 12.5 sigma sets the CUSUM's k at 6.25: even its limit 0 alarms less
    # often than its share asks (only a night past k), and the limit search halved
    # towards 0 forever. Now the CUSUM is set at 0 and the others take up the rate.
    import time

    start = time.perf_counter()
    design = design_alarms(
        730, 2.4 * URAD, step_rad=30 * URAD, nu=39, baseline_sd_ratio=5**-0.5, mc_nights=400_000
    )
    assert time.perf_counter() - start < 60
    assert design.cusum.limit == 0.0 and design.cusum.parameter == pytest.approx(6.25)
    # the scheme still gives the asked false-alarm rate, within its Monte Carlo error
    assert abs(design.check.arl0 - 730) < 3 * design.check.u_arl0
    assert design.check.step_median == 1.0
