"""Exact derivatives and the timeline: ramps, reversals, drive effects.

The one place where positions are differenced: as a test of the analytic
velocity and acceleration, with a 9-point (8th-order) central stencil on a
fine grid. With h = 0.2 ms the stencil's rounding error is ~2e-8 m/s^2 (the
position angle reaches ~20 rad, whose last bit is 4e-15 rad, i.e. 2e-16 m on a
50 mm circle, times sum|c| / h^2 = 6.4 / 4e-8) and its truncation error far
below that for the 40 Hz vibration and the 5 ms backlash take-up. Points
within a few h of a kink (reversal onsets of the spike and the vibration, ramp
breakpoints) are left out.
"""

import math
from dataclasses import replace

import numpy as np
import pytest
from numpy.testing import assert_allclose

from imu_square.program import TestProgram
from imu_square.simulate import MachineModel, chapman_machine, simulate_run
from imu_square.simulate.drive import RAMP_RING_SIZED_AT_S, add_spikes, add_start_stop_vibration
from imu_square.simulate.geometry import Geometry
from imu_square.simulate.kinematics import carriage_motion
from imu_square.simulate.trajectory import build_timeline, ramp_fraction

PROGRAM = TestProgram(radius_m=0.05, feed_m_per_s=0.05, cycles_per_direction=2, dwell_s=0.3)

# 8th-order central differences
D1 = np.array([1 / 280, -4 / 105, 1 / 5, -4 / 5, 0, 4 / 5, -1 / 5, 4 / 105, -1 / 280])
D2 = np.array([-1 / 560, 8 / 315, -1 / 5, 8 / 5, -205 / 72, 8 / 5, -1 / 5, 8 / 315, -1 / 560])

ALL_DRIVE = MachineModel(
    geometry=Geometry(
        machine_squareness_rad=15e-6,
        machine_squareness_rate_rad_s=1e-6,
        scale_x=20e-6,
        scale_y=-10e-6,
        straightness_x_m=10e-6,
        straightness_y_m=8e-6,
        axis_centre_m=(-0.1, 0.05),
        yaw_x=True,
        yaw_y=True,
    ),
    ramp_profile="s_curve",
    tau_x_s=2e-3,
    tau_y_s=3e-3,
    backlash_x_m=5e-6,
    backlash_y_m=4e-6,
    spike_x_m_s2=0.02,
    spike_y_m_s2=0.015,
    vibration_x_m_s2=0.01,
    vibration_y_m_s2=0.02,
    vibration_start_stop_m_s2=-0.015,
)


def breakpoints(timeline, machine):
    points = []
    for b in timeline.blocks:
        for tk in (b.t_start_s, b.t_end_s):
            for axis_tau in (machine.tau_x_s, machine.tau_y_s):
                for frac in (0.0, 0.5, 1.0):
                    points += [tk + axis_tau + frac * b.ramp_s, tk + axis_tau - frac * b.ramp_s]
    for axis, tau in ((0, machine.tau_x_s), (1, machine.tau_y_s)):
        times, _, _ = timeline.reversals(axis)
        points += list(times + tau)
        points += list(times + tau + machine.spike_onset * machine.spike_tau_s)
    return np.array(points)


FIRST_ORDER = MachineModel(
    tau_x_s=2e-3, tau_y_s=3e-3, servo_model="first_order", backlash_x_m=5e-6, spike_y_m_s2=0.02
)
# over-compensated: negative backlash, inward spikes that lead the reversal
SIGNED = replace(
    ALL_DRIVE, backlash_x_m=-5e-6, spike_x_m_s2=-0.02, spike_y_m_s2=0.01, spike_onset=-3.0
)


# a stick zone centred on each reversal: the symmetric spike
STICK = replace(SIGNED, spike_onset=-2.0, spike_symmetric=True)


@pytest.mark.parametrize(
    "machine",
    [MachineModel(), ALL_DRIVE, FIRST_ORDER, SIGNED, STICK],
    ids=["ideal", "all-effects", "first-order-servo", "signed-led", "stick-zone"],
)
def test_analytic_derivatives_match_finite_differences(machine):
    timeline = build_timeline(PROGRAM, machine.ramp_s, machine.ramp_profile, 0.5, 0.5)
    h = 2e-4
    t = np.arange(0.0, timeline.duration_s, h)
    pos, vel, acc = carriage_motion(timeline, machine, t)
    keep = np.ones(len(t), bool)
    for tb in breakpoints(timeline, machine):
        keep[np.abs(t - tb) < 6 * h] = False
    keep[:4] = keep[-4:] = False
    inner = keep[4:-4]
    for k in range(2):
        d1 = np.convolve(pos[:, k], D1[::-1], mode="valid") / h
        d2 = np.convolve(pos[:, k], D2[::-1], mode="valid") / h**2
        assert_allclose(d1[inner], vel[4:-4, k][inner], rtol=0, atol=2e-11)
        assert_allclose(d2[inner], acc[4:-4, k][inner], rtol=0, atol=4e-8)
    # the kinks really are few: most points are checked
    assert keep.mean() > 0.97


@pytest.mark.parametrize("profile", ["trapezoid", "s_curve"])
def test_ramp_profiles_integrate_consistently(profile):
    u = np.linspace(0, 1, 2001)
    F, f, df = ramp_fraction(u, profile)
    assert_allclose(F[-1], 0.5, rtol=1e-15)
    assert_allclose(f[[0, -1]], [0.0, 1.0], atol=1e-15)
    # F' = f and f' = df, by the trapezoidal rule / central differences
    assert_allclose(np.diff(F), 0.5 * (f[1:] + f[:-1]) * np.diff(u), atol=1e-10)
    assert_allclose(np.gradient(f, u)[1:-1], df[1:-1], atol=2e-3)


@pytest.mark.parametrize("profile", ["trapezoid", "s_curve"])
def test_block_timing_and_mirror_symmetry(profile):
    timeline = build_timeline(PROGRAM, 0.15, profile, 3.0, 3.0)
    b = timeline.blocks[0]
    assert_allclose(b.duration_s, PROGRAM.block_duration_s + 0.15, rtol=1e-15)
    assert timeline.blocks[1].t_start_s == pytest.approx(b.t_end_s + 0.3, rel=1e-15)
    assert_allclose(timeline.duration_s, 3.0 + 2 * b.duration_s + 0.3 + 3.0, rtol=1e-15)
    tau = np.linspace(0.0, b.duration_s, 1001)
    s, ds, dds = b.progress(b.t_start_s + tau)
    s_rev, ds_rev, dds_rev = b.progress(b.t_end_s - tau)
    assert_allclose(s + s_rev, b.angle_rad, rtol=1e-13)
    assert_allclose(ds, ds_rev, rtol=1e-12, atol=1e-15)
    assert_allclose(dds, -dds_rev, rtol=1e-9, atol=1e-12)
    # the middle of the motion maps to half the block angle (the eps_c anchor)
    mid, _, _ = b.progress(np.array([0.5 * (b.t_start_s + b.t_end_s)]))
    assert_allclose(mid, 0.5 * b.angle_rad, rtol=1e-14)
    # time_at_progress inverts progress, ramps included
    for q in (0.0, 0.001, 0.05, 1.0, b.angle_rad - 0.002, b.angle_rad):
        tq = b.time_at_progress(q)
        assert_allclose(b.progress(np.array([tq]))[0], q, atol=1e-12)


def test_reversals_on_the_ramped_timeline():
    program = TestProgram(radius_m=0.05, feed_m_per_s=0.05, cycles_per_direction=2, dwell_s=0.3)
    timeline = build_timeline(program, 0.15, "trapezoid", 1.0, 1.0)
    t = np.arange(0.0, timeline.duration_s, 1e-4)
    for axis in (0, 1):
        times, dirs, initial = timeline.reversals(axis)
        _, v, _ = timeline.axis_path(t, axis)
        # the velocity has the announced direction between reversals
        edges = np.concatenate(([0.0], times, [timeline.duration_s]))
        for k, d in enumerate(np.concatenate(([initial], dirs))):
            m = (t > edges[k] + 1e-3) & (t < edges[k + 1] - 1e-3) & (np.abs(v) > 1e-9)
            assert np.all(np.sign(v[m]) == d)
        assert np.all(np.diff(dirs) != 0)
    # X starts at phi = 0 moving to -x, reverses at phi = pi (t = lead-in + ramp/2 + pi/omega)
    times, dirs, initial = timeline.reversals(0)
    assert initial == -1
    assert_allclose(times[0], 1.0 + 0.075 + math.pi, rtol=1e-14)
    assert dirs[0] == 1


def test_reversal_spike_peak_and_backlash_size():
    machine = MachineModel(spike_x_m_s2=0.02, backlash_y_m=6e-6)
    timeline = build_timeline(PROGRAM, machine.ramp_s, machine.ramp_profile, 0.5, 0.5)
    t = np.arange(0.0, timeline.duration_s, 1e-4)
    _, _, acc0 = carriage_motion(timeline, MachineModel(), t)
    pos, vel, acc = carriage_motion(timeline, machine, t)
    pos0, vel0, _ = carriage_motion(timeline, MachineModel(), t)
    bump = acc[:, 0] - acc0[:, 0]
    times, dirs, _ = timeline.reversals(0)
    # 5 inside each block (phi = pi .. 5 pi) and one at the start of the CW block
    assert len(times) == 11
    for tk, dk in zip(times, dirs, strict=True):
        i = np.searchsorted(t, tk)
        # 2 h / tau^2 (1 - 2u + u^2/2) e^-u just after the reversal
        u = (t[i] - tk) / 0.02
        assert_allclose(bump[i], -dk * 0.02 * (1 - 2 * u + 0.5 * u * u) * math.exp(-u), rtol=1e-9)
        # the bump has zero area: no net velocity change 1 s (50 tau) later
        j = np.searchsorted(t, tk + 1.0)
        assert abs(vel[j, 0] - vel0[j, 0]) < 1e-15
    lag = pos[:, 1] - pos0[:, 1]
    # y lags its motion by b/2: while moving +y the offset is -3 um
    _, v, _ = timeline.axis_path(t, 1)
    far = np.ones(len(t), bool)
    for tk in timeline.reversals(1)[0]:
        far[np.abs(t - tk) < 0.2] = False
    moving = far & (np.abs(v) > 1e-3)
    assert_allclose(lag[moving], -3e-6 * np.sign(v[moving]), rtol=1e-9)


def test_chapman_yaw_rotates_the_sensor_with_the_carriage():
    g = chapman_machine(3)
    assert_allclose(g.carriage_yaw(np.array([-0.4, 0.4]), 0.0), [-50e-6, 50e-6], rtol=1e-12)
    program = TestProgram(
        radius_m=0.05, feed_m_per_s=0.05, cycles_per_direction=2, dwell_s=0.3, centre_m=(0.2, 0.0)
    )
    _, truth = simulate_run(program, MachineModel(geometry=g), seed=0, lead_in_s=0.5)
    assert_allclose(truth["carriage_yaw_rad"], 25e-6, rtol=1e-12)
    assert_allclose(truth["local_machine_squareness_rad"], 15e-6, rtol=1e-12)


def test_the_yaw_of_a_quartic_form_on_both_sides_of_the_centre_is_its_slope():
    # X**3 is the reference: the library's power, on negative X as much as on positive
    g = chapman_machine(7, yaw=True)
    x = np.linspace(-0.375, 0.375, 10001)
    reference = g.k_x * x + 4 * g.q_x * x**3 - g.k_y * 0.1
    # atol: 1e-14 of the yaw (~1e-4 rad), where the two terms cancel
    assert_allclose(g.carriage_yaw(x, 0.1), reference, rtol=1e-13, atol=1e-18)


@pytest.mark.parametrize("onset", [0.0, -2.0, -4.0])
@pytest.mark.parametrize("peak", [0.02, -0.03])
def test_spike_sign_and_timing_around_the_reversal(onset, peak):
    """The bump's acceleration peak is ``peak`` (outward: against the new direction's
    lag, i.e. along ``-d``), at ``onset * tau`` from the reversal; its area is zero."""
    tau = 0.01
    t = np.arange(-0.2, 0.4, 1e-5)
    p = [np.zeros_like(t) for _ in range(3)]
    add_spikes(p, t, np.array([0.0]), np.array([1]), peak, tau, onset)
    i = int(np.argmax(np.abs(p[2])))
    assert t[i] == pytest.approx(onset * tau, abs=2e-5)
    assert p[2][i] == pytest.approx(-peak, rel=1e-3)  # d = +1: the bump is -d h ...
    # zero area: the sum misses only half of the step at the onset (peak * dt / 2)
    assert np.sum(p[2]) * 1e-5 == pytest.approx(0.0, abs=1e-5 * abs(peak))
    assert p[0][t < onset * tau - 1e-9].max(initial=0.0) == 0.0  # nothing before its onset
    # the position peak, h e^-2 (4 h / e^2 at u = 2), is at (onset + 2) tau
    j = int(np.argmax(np.abs(p[0])))
    assert t[j] == pytest.approx((onset + 2) * tau, abs=2e-5)


@pytest.mark.parametrize("d", [1, -1])
def test_symmetric_spike_is_a_stick_zone_around_the_reversal(d):
    """Through a reversal at acceleration ``a_r`` the symmetric spike of peak
    ``-a_r`` leaves the table ``tanh^2(t / tau)`` of the commanded velocity: it
    stands still at the reversal and the error is an even bump, back to zero."""
    tau, a_r = 0.01, 0.05
    t = np.linspace(-0.3, 0.3, 60001)
    p = [np.zeros_like(t) for _ in range(3)]
    add_spikes(p, t, np.array([0.0]), np.array([d]), -a_r, tau, onset=-2.0, symmetric=True)
    v_command = d * a_r * t
    assert_allclose(v_command + p[1], v_command * np.tanh(t / tau) ** 2, rtol=0, atol=1e-15)
    # even in time; inward (along d) by a_r tau^2 ln 2 at the reversal, where the
    # acceleration is largest, a_r; zero net impulse and displacement at both ends
    assert_allclose(p[0], p[0][::-1], rtol=0, atol=1e-13 * a_r * tau**2)
    centre = t.size // 2
    assert p[0][centre] == pytest.approx(d * a_r * tau**2 * math.log(2), rel=1e-12)
    assert np.abs(p[2]).max() == pytest.approx(a_r, rel=1e-12)
    assert abs(p[2][centre]) == pytest.approx(a_r, rel=1e-12)
    assert_allclose([p[0][0], p[0][-1], p[1][0], p[1][-1]], 0.0, atol=1e-18)
    assert np.sum(p[2]) * 1e-5 == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("onset", [0.0, -4.0])
def test_symmetric_spike_peaks_where_the_skewed_one_does(onset):
    tau = 0.01
    t = np.arange(-0.3, 0.4, 1e-5)
    peaks = []
    for symmetric in (False, True):
        p = [np.zeros_like(t) for _ in range(3)]
        add_spikes(p, t, np.array([0.0]), np.array([1]), 0.02, tau, onset, symmetric)
        peaks.append(t[int(np.argmax(np.abs(p[0])))])
        # outward (along -d) for a positive peak, in either form
        assert p[0].max() == 0.0 and p[0].min() < 0.0
    assert_allclose(peaks, (onset + 2) * tau, atol=2e-5)


@pytest.mark.parametrize("size", [0.02, -0.01])
def test_structural_mode_rung_at_the_corners_of_the_feed_ramps(size):
    # the mode at 40 Hz rung along the acceleration step at each corner of the ramps
    machine = MachineModel(vibration_start_stop_m_s2=size, vibration_hz=40.0)
    # a dwell long enough for one block's end ringing to have died at the next one's start
    program = replace(PROGRAM, dwell_s=3.0)
    timeline = build_timeline(program, machine.ramp_s, machine.ramp_profile, 0.5, 0.5)
    t = np.arange(0.0, timeline.duration_s, 1e-4)
    _, _, plain = carriage_motion(timeline, MachineModel(), t)
    _, _, rung = carriage_motion(timeline, machine, t)
    ring = rung - plain
    ramp = machine.ramp_s
    corners = [
        tk for b in timeline.blocks for tk in (b.t_start_s, b.t_start_s + ramp, b.t_end_s - ramp)
    ] + [b.t_end_s for b in timeline.blocks]
    near = np.zeros(t.size, bool)
    for tk in corners:
        near |= (t >= tk) & (t < tk + 35.0 / (0.05 * 2 * math.pi * 40.0))
    assert np.all(ring[~near] == 0.0)
    wn = 2 * math.pi * 40.0
    sigma, wd = 0.05 * wn, wn * math.sqrt(1 - 0.05**2)
    period = 2 * math.pi / wd

    def response(u):
        # acceleration of the mode rung with a unit size, u after the step: sized 30 ms on
        c, s = math.cos(wd * u), math.sin(wd * u)
        shape = sigma**2 + (wd**2 - sigma**2) * c - 2 * sigma * wd * s
        return math.exp(-sigma * (u - RAMP_RING_SIZED_AT_S)) * shape / wd**2

    def rung_at(at):
        return (
            carriage_motion(timeline, machine, at)[2]
            - carriage_motion(timeline, MachineModel(), at)[2]
        )

    for b in timeline.blocks:
        ramp_angle = b.sign * 0.5 * b.omega_rad_s * ramp
        # up along the motion at its start and end, down at the ramps' inner corners
        steps = [
            (b.t_start_s, b.start_angle_rad, 1.0),
            (b.t_start_s + ramp, b.start_angle_rad + ramp_angle, -1.0),
            (b.t_end_s - ramp, b.end_angle_rad - ramp_angle, -1.0),
            (b.t_end_s, b.end_angle_rad, 1.0),
        ]
        for tk, _, _ in steps:
            # at each corner and five periods later: the steps so far, each rung at the damped
            # frequency and decayed with the damping ratio since
            at = np.array([tk, tk + 5 * period])
            expected = sum(
                step
                * size
                * b.sign
                * np.array([-math.sin(phi), math.cos(phi)])
                * np.array([response(u - tc) for u in at])[:, None]
                for tc, phi, step in steps
                if tc <= tk
            )
            assert_allclose(rung_at(at), expected, rtol=1e-9, atol=1e-12)
    # the first corner alone: the step's own initial acceleration, along the motion, is the
    # size grown back over the 30 ms it is sized at (exp(0.05 * 2 pi 40 * 0.03) = 1.46)
    b = timeline.blocks[0]
    first = b.sign * np.array([-math.sin(b.start_angle_rad), math.cos(b.start_angle_rad)])
    initial = size * math.exp(sigma * 0.03) * first
    assert_allclose(rung_at(np.array([b.t_start_s]))[0], initial, rtol=1e-9, atol=1e-12)


def test_block_edge_ringing_is_off_by_default_and_in_the_truth():
    assert MachineModel().vibration_start_stop_m_s2 == 0.0
    assert MachineModel().vibration_start_stop_quadrature_m_s2 == 0.0
    quadrature = MachineModel(vibration_start_stop_quadrature_m_s2=-0.01).effects()
    assert quadrature["structural_vibration"]["start_stop_quadrature_m_s2"] == -0.01
    effects = MachineModel(vibration_start_stop_m_s2=0.01).effects()
    assert effects["structural_vibration"]["start_stop_m_s2"] == 0.01
    assert (
        "start_stop_m_s2"
        not in MachineModel(vibration_x_m_s2=0.01).effects()["structural_vibration"]
    )


def test_the_quadrature_ringing_of_a_ramp_corner_starts_with_zero_acceleration():
    # a smooth ramp's jerk step rings the mode a quarter period after an acceleration step
    # would: zero acceleration at the corner, then Q e^(-sigma t) sin(omega_d t) along the step
    hz, zeta, q = 80.0, 0.05, 0.02
    wn = 2 * math.pi * hz
    sigma, wd = zeta * wn, wn * math.sqrt(1 - zeta**2)
    dt = 1e-6
    t = dt * np.arange(-10_000, 1_500_000)  # t = 0 exactly
    p = [np.zeros_like(t) for _ in range(3)]
    add_start_stop_vibration(p, t, np.array([0.0]), np.array([-0.6]), 0.0, hz, zeta, q)
    at = np.searchsorted(t, 0.0)
    assert np.all(p[2][:at] == 0.0) and abs(p[2][at]) < 1e-12
    # sized 30 ms on: the jerk at the corner is -0.6 Q omega_d exp(30 ms sigma) (a forward
    # difference over 1 us: 5e-5 short)
    grown = math.exp(sigma * 0.03)
    assert_allclose((p[2][at + 1] - p[2][at]) / dt, -0.6 * q * grown * wd, rtol=2e-4)
    # the path's derivatives are exact
    assert_allclose(np.gradient(p[0], dt)[at + 5 : -5], p[1][at + 5 : -5], atol=1e-11)
    assert_allclose(np.gradient(p[1], dt)[at + 5 : -5], p[2][at + 5 : -5], atol=1e-7)
    # a quarter period on: the sine's crest, within 2 zeta (the non-oscillating part)
    quarter = np.searchsorted(t, 0.25 / hz * math.sqrt(1 - zeta**2))
    crest = -0.6 * q * grown * math.exp(-sigma * t[quarter])
    assert_allclose(p[2][quarter], crest, rtol=2.5 * zeta)
    # and it has died, position and all (the drifting omega_d t of the path too)
    assert np.abs(p[0][t > 1.3]).max() < 1e-9 * q / wd**2
    # its envelope is Q 30 ms on: the crest nearest 30 ms, decayed from there (within 2 zeta)
    crest_t = (round(0.03 * wd / math.pi - 0.5) + 0.5) * math.pi / wd
    expected = 0.6 * q * math.exp(-sigma * (crest_t - 0.03))
    assert_allclose(abs(p[2][np.searchsorted(t, crest_t)]), expected, rtol=2.5 * zeta)
