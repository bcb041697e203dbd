"""The baseline's statistics and a night's change against it (monitor/baseline.py)."""

import math

import numpy as np
import pytest

from imu_square.monitor.stats.baseline import (
    MIN_RUNS,
    REMOUNT_FLOOR_RAD,
    REMOUNT_SIGMAS,
    BaselineError,
    RunValue,
    change_since,
    compute_baseline,
    remount_tolerance,
)

EPS = math.radians(2.1)


def _run(s, u=18e-6, eps=EPS, u_eps=1.5e-4, dof=14, day=1):
    return RunValue(s, u, dof, eps, u_eps, f"2026-10-{day:02d}T02:30:00Z")


def test_baseline_is_the_mean_with_the_larger_of_scatter_and_stated_u():
    runs = [_run(s, day=i + 1) for i, s in enumerate((100e-6, 130e-6, 70e-6, 120e-6))]
    b = compute_baseline(runs)
    assert b.squareness_rad == pytest.approx(105e-6)
    sd = float(np.std([100e-6, 130e-6, 70e-6, 120e-6], ddof=1))
    assert b.sd_rad == pytest.approx(sd)
    # scatter (26 µm/m) above the stated 18 µm/m: type A of the mean, n - 1 dof
    assert b.u_squareness_rad == pytest.approx(sd / 2) and b.dof == 3
    assert (b.first_recorded_at, b.last_recorded_at, b.n_runs) == (
        "2026-10-01T02:30:00Z",
        "2026-10-04T02:30:00Z",
        4,
    )
    # three runs that agree by chance do not make it overconfident: the stated u rules
    lucky = compute_baseline([_run(s, day=i + 1) for i, s in enumerate((100e-6, 101e-6, 99e-6))])
    assert lucky.u_squareness_rad == pytest.approx(18e-6 / math.sqrt(3))
    assert lucky.dof == 3 * 14


def test_too_few_runs_or_a_moved_sensor_are_refused():
    with pytest.raises(BaselineError, match=f"at least {MIN_RUNS} valid runs, got 2"):
        compute_baseline([_run(0.0), _run(0.0)])
    runs = [_run(0.0, day=1), _run(0.0, day=2), _run(0.0, eps=EPS + math.radians(0.5), day=3)]
    with pytest.raises(BaselineError, match="the sensor moved among the baseline's runs"):
        compute_baseline(runs)


def test_change_is_divided_by_cos_2eps_and_combines_both_uncertainties():
    eps = math.radians(8.0)
    b = compute_baseline(
        [_run(5e-3 + d, eps=eps, day=i + 1) for i, d in enumerate((0, 1e-6, -1e-6))]
    )
    night = _run(5e-3 + 10e-6 * math.cos(2 * eps), eps=eps, day=20)
    ch = change_since(b, night)
    assert ch.change_rad == pytest.approx(10e-6, rel=1e-9)
    expected_u = math.hypot(18e-6, b.u_squareness_rad) / math.cos(2 * eps)
    assert ch.u_change_rad == pytest.approx(expected_u)
    # Welch-Satterthwaite between the night's 14 and the baseline's 42 dof
    vs, vb = 18e-6**2, b.u_squareness_rad**2
    assert ch.dof == pytest.approx((vs + vb) ** 2 / (vs**2 / 14 + vb**2 / b.dof))
    assert not ch.remounted and ch.z == pytest.approx(ch.change_rad / ch.u_change_rad)


@pytest.mark.parametrize(
    ("shift_deg", "remounted"),
    [(0.0, False), (0.015, False), (-0.015, False), (0.025, True), (0.06, True), (-3.0, True)],
)
def test_a_remount_is_an_eps_c_jump_beyond_the_floor_when_the_runs_agree(shift_deg, remounted):
    # five identical eps_c: no scatter, so the 0.02 deg floor is the tolerance
    b = compute_baseline([_run(0.0, day=i + 1) for i in range(5)])
    assert remount_tolerance([EPS] * 5) == pytest.approx(REMOUNT_FLOOR_RAD)
    ch = change_since(b, _run(0.0, eps=EPS + math.radians(shift_deg), day=20))
    assert ch.remounted is remounted
    assert ch.eps_c_shift_rad == pytest.approx(math.radians(shift_deg), abs=1e-12)


def test_the_remount_tolerance_grows_with_the_nights_scatter():
    # sd 0.0082 deg over 4 runs: 8 sd sqrt(1 + 1/4) = 0.073 deg, above the floor
    eps = EPS + np.radians([0.0, 0.01, -0.01, 0.0])
    sd = float(np.std(eps, ddof=1))
    assert remount_tolerance(eps) == pytest.approx(REMOUNT_SIGMAS * sd * math.sqrt(1.25))
    assert remount_tolerance(eps) > 3 * REMOUNT_FLOOR_RAD
    b = compute_baseline([_run(0.0, eps=e, day=i + 1) for i, e in enumerate(eps)])
    tol = remount_tolerance(eps)
    assert not change_since(b, _run(0.0, eps=EPS + 0.9 * tol, day=20), tol).remounted
    assert change_since(b, _run(0.0, eps=EPS + 1.1 * tol, day=20), tol).remounted
