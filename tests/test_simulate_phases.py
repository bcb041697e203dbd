"""The simulator's X/Y phases follow docs/model.md, in the time domain, CCW and CW.

Noise-free runs; the phases of ``cos(omega t + psi)`` are fitted with numpy
lstsq over the whole analysed cycles of each block; ``psi_y - psi_x`` minus the
nominal quadrature (-pi/2 for CCW, +pi/2 for CW) must be ``-(alpha + beta) - m``
for CCW and ``+(alpha + beta) - m`` for CW, to 0.1 urad. A perfect circle
sampled as float32 is reproduced to ~1e-4 urad, so 0.1 urad leaves room only
for second-order terms of the model itself (alpha^3/3 ~ 3e-4 urad at 1 mrad).
"""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from imu_square.program import TestProgram
from imu_square.simulate import (
    Geometry,
    MachineModel,
    SensorModel,
    chapman_machine,
    simulate_run,
    with_effects,
)
from imu_square.simulate.kinematics import carriage_motion
from imu_square.simulate.trajectory import build_timeline

PROGRAM = TestProgram(radius_m=0.05, feed_m_per_s=0.05, cycles_per_direction=3, dwell_s=0.5)
SENSOR = SensorModel(sample_rate_hz=200.0)
TOL = 0.1e-6


def block_fits(recording, truth):
    """Per block: (direction, [amplitude, psi] of x, of y) over its whole analysed cycles."""
    t = recording.time_s
    accel = recording.accel.astype(float)
    omega = truth["omega_rad_s"] / (1.0 + truth["clock_ppm"] * 1e-6)
    period = 2 * math.pi / omega
    out = []
    for b in truth["blocks"]:
        t0 = b["analysed_start_s"]
        n_cycles = math.floor((b["analysed_end_s"] - t0) / period + 1e-9)
        m = (t >= t0) & (t < t0 + n_cycles * period)
        design = np.column_stack([np.cos(omega * t[m]), np.sin(omega * t[m]), np.ones(m.sum())])
        fits = []
        for k in range(2):
            (c, s, _), *_ = np.linalg.lstsq(design, accel[m, k], rcond=None)
            fits.append((math.hypot(c, s), math.atan2(-s, c)))
        out.append((b["direction"], fits[0], fits[1]))
    return out


def phase_deviation(recording, truth):
    """Per direction: psi_y - psi_x minus the nominal quadrature. [rad]"""
    out = {}
    for direction, fx, fy in block_fits(recording, truth):
        nominal = -math.pi / 2 if direction == "ccw" else math.pi / 2
        out[direction] = math.remainder(fy[1] - fx[1] - nominal, 2 * math.pi)
    return out


def run(machine=None, sensor=SENSOR, program=PROGRAM):
    return simulate_run(program, machine, sensor, seed=0, lead_in_s=1.0, lead_out_s=1.0)


@pytest.mark.parametrize(
    ("machine", "sensor", "square", "m"),
    [
        (MachineModel(geometry=Geometry(machine_squareness_rad=500e-6)), SENSOR, 500e-6, 0.0),
        (MachineModel(geometry=Geometry(machine_squareness_rad=-80e-6)), SENSOR, -80e-6, 0.0),
        (None, SensorModel(sample_rate_hz=200.0, beta_rad=300e-6), 300e-6, 0.0),
        (MachineModel(tau_x_s=1e-3, tau_y_s=3e-3), SENSOR, 0.0, 2e-3),
        (MachineModel(tau_x_s=4e-3, tau_y_s=1e-3), SENSOR, 0.0, -3e-3),
        (
            MachineModel(
                geometry=Geometry(machine_squareness_rad=15e-6),
                tau_x_s=2e-3,
                tau_y_s=2.5e-3,
                ramp_profile="s_curve",
            ),
            SensorModel(sample_rate_hz=200.0, beta_rad=-40e-6),
            -25e-6,
            0.5e-3,
        ),
    ],
    ids=["alpha", "alpha-negative", "beta", "servo", "servo-negative", "combined-s-curve"],
)
def test_time_domain_phases_follow_the_model(machine, sensor, square, m):
    recording, truth = run(machine, sensor)
    assert_allclose(truth["squareness_rad"], square, atol=1e-15)
    assert_allclose(truth["servo_mismatch_rad"], m, atol=1e-15)
    dev = phase_deviation(recording, truth)
    assert_allclose(dev["ccw"], -square - m, atol=TOL)
    assert_allclose(dev["cw"], +square - m, atol=TOL)


def test_sensor_rotation_shifts_both_phases_equally():
    eps = math.radians(2.1)
    rec0, truth0 = run()
    rec1, truth1 = run(sensor=SensorModel(sample_rate_hz=200.0, eps_c_rad=eps))
    assert truth1["eps_c_rad"] == eps
    for (d, fx0, fy0), (_, fx1, fy1) in zip(
        block_fits(rec0, truth0), block_fits(rec1, truth1), strict=True
    ):
        # time domain: a rotation by +eps delays both channels' phase by sign * eps
        sign = 1 if d == "ccw" else -1
        assert_allclose(fx1[1] - fx0[1], -sign * eps, atol=TOL)
        assert_allclose(fy1[1] - fy0[1], -sign * eps, atol=TOL)
    assert_allclose(list(phase_deviation(rec1, truth1).values()), [0.0, 0.0], atol=TOL)


def test_rotation_scales_machine_squareness_by_cos_2eps():
    """Second order: in a frame turned by eps the sheared circle shows alpha cos(2 eps).

    The table of docs/model.md is first order; the sensor non-orthogonality,
    applied in the sensor frame, is not scaled.
    """
    alpha, beta, eps = 1000e-6, 200e-6, math.radians(2.1)
    recording, _truth = run(
        MachineModel(geometry=Geometry(machine_squareness_rad=alpha)),
        SensorModel(sample_rate_hz=200.0, eps_c_rad=eps, beta_rad=beta),
    )
    dev = phase_deviation(recording, _truth)
    expected = alpha * math.cos(2 * eps) + beta
    assert_allclose(dev["ccw"], -expected, atol=TOL)
    assert_allclose(dev["cw"], expected, atol=TOL)
    assert abs(expected - (alpha + beta)) > 20 * TOL  # the effect is resolved


def test_off_centre_straightness_measures_local_squareness():
    """Chapman machine 2 (X bow, no yaw) at x = 200 mm: the circle sees 15 - 50/2 = -10 um/m."""
    geometry = chapman_machine(2)
    program = TestProgram(
        radius_m=0.05, feed_m_per_s=0.05, cycles_per_direction=3, dwell_s=0.5, centre_m=(0.2, 0.1)
    )
    recording, truth = run(MachineModel(geometry=geometry), program=program)
    assert_allclose(truth["local_machine_squareness_rad"], -10e-6, atol=1e-12)
    assert_allclose(truth["squareness_rad"], 15e-6, atol=1e-15)
    dev = phase_deviation(recording, truth)
    assert_allclose(dev["ccw"], -truth["local_machine_squareness_rad"], atol=TOL)
    assert_allclose(dev["cw"], truth["local_machine_squareness_rad"], atol=TOL)


def test_gravity_coupling_phase_matches_truth():
    machine = MachineModel(tilt_per_m=(0.0, 1e-4, 0.0, 0.0))
    recording, truth = run(machine)
    # g k r / A = 9.80665 * 1e-4 * 0.05 / 0.05 ~ 0.98 mrad
    assert_allclose(truth["gravity_phase_rad"], math.atan(9.80665e-4), rtol=1e-12)
    dev = phase_deviation(recording, truth)
    assert_allclose(dev["ccw"], -truth["gravity_phase_rad"], atol=TOL)
    assert_allclose(dev["cw"], truth["gravity_phase_rad"], atol=TOL)


def test_gravity_coupling_amplitude_is_g_k_r():
    k = 2e-4
    rec0, truth = run()
    rec1, _ = run(MachineModel(tilt_per_m=(k, 0.0, 0.0, 0.0)))
    diff = rec1.accel[:, 0].astype(float) - rec0.accel[:, 0].astype(float)
    t = rec0.time_s
    omega = truth["omega_rad_s"]
    for b in truth["blocks"]:
        m = (t >= b["analysed_start_s"]) & (t < b["analysed_start_s"] + 2 * 2 * math.pi / omega)
        design = np.column_stack([np.cos(omega * t[m]), np.sin(omega * t[m])])
        (c, s), *_ = np.linalg.lstsq(design, diff[m], rcond=None)
        assert_allclose(math.hypot(c, s), 9.80665 * k * PROGRAM.radius_m, rtol=1e-5)


def test_centripetal_amplitude_is_v2_over_r():
    a = PROGRAM.centripetal_m_s2
    recording, truth = run()
    assert truth["amplitude_m_s2"] == pytest.approx(a, rel=1e-15)
    for _, fx, fy in block_fits(recording, truth):
        # float32 samples: the fit of ~1900 samples averages their rounding
        assert_allclose([fx[0], fy[0]], [a, a], rtol=1e-7)
    # the float64 physics itself, before the sensor stores float32: 1e-9 relative
    timeline = build_timeline(PROGRAM, 0.15, "trapezoid", 1.0, 1.0)
    for b in timeline.blocks:
        t0, _ = b.analysed_window_s
        t = t0 + np.arange(0, 3 * PROGRAM.period_s, 1e-3)
        _, _, acc = carriage_motion(timeline, MachineModel(), t)
        design = np.column_stack([np.cos(b.sign * t), np.sin(b.sign * t)])
        for k in range(2):
            coef, *_ = np.linalg.lstsq(design, acc[:, k], rcond=None)
            assert_allclose(np.hypot(*coef), a, rtol=1e-9)


def test_drifting_squareness_and_beta_are_measured_at_their_window_means():
    machine = MachineModel(
        geometry=Geometry(machine_squareness_rad=20e-6, machine_squareness_rate_rad_s=1e-6)
    )
    sensor = SensorModel(sample_rate_hz=200.0, beta_rad=10e-6, beta_0_rad=60e-6, tau_warm_s=20.0)
    recording, truth = run(machine, sensor)
    windows = [(b["analysed_start_s"], b["analysed_end_s"]) for b in truth["blocks"]]
    t_mid = np.mean([0.5 * (a + b) for a, b in windows])
    assert_allclose(truth["machine_squareness_rad"], 20e-6 + 1e-6 * t_mid, rtol=1e-12)
    dev = phase_deviation(recording, truth)
    # CCW sees the means over its window, CW over its; equal windows: their mean is the truth
    assert_allclose(0.5 * (dev["cw"] - dev["ccw"]), truth["squareness_rad"], atol=TOL)
    assert abs(dev["cw"] + dev["ccw"]) > 1e-6  # the drift between the blocks is resolved


def measured_theta_diff(recording, truth):
    """theta_y - theta_x, mean of CCW and flipped CW, position-angle domain. [rad]"""
    dev = phase_deviation(recording, truth)
    return 0.5 * (dev["cw"] - dev["ccw"])


@pytest.mark.parametrize(
    ("machine", "sensor", "centre_m", "expected"),
    [
        # Chapman machine 2 at (200, -100) mm: the circle sees 15 - 50/2 = -10 um/m
        (MachineModel(geometry=chapman_machine(2)), SENSOR, (0.2, -0.1), -10e-6),
        # the gravity_coupling preset: atan(g k r / A) = 980.66 urad, no squareness at all
        (with_effects(["gravity_coupling"], None, SENSOR)[0], SENSOR, (0.0, 0.0), 980.66e-6),
        # machine 5 (both bows with yaw) off centre, beta and a small gravity coupling
        (
            MachineModel(geometry=chapman_machine(5), tilt_per_m=(2e-6, 5e-6, -3e-6, 1e-6)),
            SensorModel(sample_rate_hz=200.0, beta_rad=40e-6),
            (0.2, -0.1),
            None,
        ),
    ],
    ids=["chapman-2-off-centre", "gravity-preset", "chapman-5-beta-gravity"],
)
def test_expected_squareness_is_what_the_circle_measures(machine, sensor, centre_m, expected):
    """``squareness_rad`` is the global alpha + beta; the circle measures
    local_machine_squareness + beta + gravity_phase (first order), here to 0.1 urad."""
    program = TestProgram(
        radius_m=0.05, feed_m_per_s=0.05, cycles_per_direction=3, dwell_s=0.5, centre_m=centre_m
    )
    recording, truth = run(machine, sensor, program)
    measured = measured_theta_diff(recording, truth)
    if expected is not None:
        assert_allclose(measured, expected, atol=0.01e-6)
    first = (
        truth["local_machine_squareness_rad"]
        + truth["sensor_squareness_rad"]
        + truth["gravity_phase_rad"]
    )
    assert_allclose(first, measured, atol=TOL)
    assert_allclose(truth["expected_squareness_rad"], measured, atol=TOL)
    assert abs(truth["squareness_rad"] - measured) > 10e-6  # the distinction matters here


def test_expected_squareness_includes_the_rotation():
    """eps_c = 30 deg with machine 5 off centre and beta: the exact expectation
    (alpha -> alpha cos 2 eps, etc.) matches the fit, the first-order one does not."""
    program = TestProgram(
        radius_m=0.05, feed_m_per_s=0.05, cycles_per_direction=3, dwell_s=0.5, centre_m=(0.2, -0.1)
    )
    sensor = SensorModel(sample_rate_hz=200.0, eps_c_rad=math.radians(30.0), beta_rad=40e-6)
    recording, truth = run(MachineModel(geometry=chapman_machine(5)), sensor, program)
    measured = measured_theta_diff(recording, truth)
    assert_allclose(truth["expected_squareness_rad"], measured, atol=TOL)
    first = (
        truth["local_machine_squareness_rad"]
        + truth["sensor_squareness_rad"]
        + truth["gravity_phase_rad"]
    )
    assert abs(first - measured) > 10e-6


def test_mean_theta_is_eps_c_plus_carriage_yaw_minus_rotation_part_of_j():
    """(theta_x + theta_y)/2 = eps_c + yaw - (J_yx - J_xy)/2 + beta/2 (docs/model.md, Truth),
    read in the position-angle domain from the ideal-timeline phase of each block."""
    centre = (0.2, -0.1)
    program = TestProgram(
        radius_m=0.05, feed_m_per_s=0.05, cycles_per_direction=3, dwell_s=0.5, centre_m=centre
    )
    geometry = chapman_machine(5)
    sensor = SensorModel(sample_rate_hz=200.0, eps_c_rad=0.01, beta_rad=40e-6)
    recording, truth = run(MachineModel(geometry=geometry), sensor, program)
    timeline = build_timeline(program, 0.15, "trapezoid", 1.0, 1.0)
    phi, _, _ = timeline.angle(recording.time_s - recording.time_s[0])
    accel = recording.accel.astype(float)
    thetas = []
    for b in truth["blocks"]:
        m = (recording.time_s >= b["analysed_start_s"]) & (recording.time_s < b["analysed_end_s"])
        design = np.column_stack([np.ones(m.sum()), np.cos(phi[m]), np.sin(phi[m])])
        (_, px, qx), *_ = np.linalg.lstsq(design, accel[m, 0], rcond=None)
        (_, py, qy), *_ = np.linalg.lstsq(design, accel[m, 1], rcond=None)
        # a_x = -A cos(phi - theta_x), a_y = -A sin(phi - theta_y)
        thetas += [math.atan2(-qx, -px), math.atan2(py, -qy)]
    _, jxy, jyx, _ = (float(v) for v in geometry.jacobian(*centre))
    expected = truth["eps_c_rad"] + truth["carriage_yaw_rad"] - (jyx - jxy) / 2
    expected += truth["sensor_squareness_rad"] / 2
    assert truth["carriage_yaw_rad"] != 0.0
    assert_allclose(np.mean(thetas), expected, atol=TOL)
