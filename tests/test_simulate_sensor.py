"""The sensor stage: noise spectra, ADC, clipping, clock error, drift, gain, reproducibility."""

import math
from dataclasses import replace

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.signal import welch

from imu_square.program import TestProgram
from imu_square.simulate import MachineModel, SensorModel, simulate_run, with_effects
from imu_square.simulate.sensor_noise import sensor_noise
from imu_square.units import G

PROGRAM = TestProgram(radius_m=0.05, feed_m_per_s=0.05, cycles_per_direction=2, dwell_s=0.3)


def test_white_noise_density_matches_request():
    d, fs = 7e-6 * G, 1000.0
    noise = sensor_noise(2**18, fs, d, 0.0, np.random.default_rng(1))
    f, psd = welch(noise, fs=fs, nperseg=4096, axis=0)
    band = (f > 1.0) & (f < 450.0)
    assert_allclose(psd[band].mean(axis=0), d**2, rtol=0.05)
    # independent axes
    assert abs(np.corrcoef(noise.T)[0, 1]) < 0.01


def test_flicker_noise_has_the_requested_corner():
    d, fs, fc = 10e-6 * G, 200.0, 2.0
    noise = sensor_noise(2**19, fs, d, fc, np.random.default_rng(2), n_axes=1)
    f, psd = welch(noise[:, 0], fs=fs, nperseg=2**14)
    expected = d**2 * (1 + fc / f[1:])
    ratio = psd[1:] / expected
    for lo, hi in ((0.05, 0.5), (0.5, 5.0), (5.0, 90.0)):
        band = (f[1:] > lo) & (f[1:] < hi)
        assert_allclose(ratio[band].mean(), 1.0, rtol=0.05)
    # at the corner the PSD is twice the white level
    k = np.argmin(np.abs(f - fc))
    assert_allclose(psd[k - 20 : k + 21].mean() / d**2, 2.0, rtol=0.1)


def test_recording_noise_is_white_at_the_requested_density():
    d = 20e-6 * G
    sensor = SensorModel(sample_rate_hz=500.0, noise_density_m_s2_rthz=d)
    rec_noisy, _ = simulate_run(PROGRAM, None, sensor, seed=5, lead_in_s=1.0)
    rec_clean, _ = simulate_run(
        PROGRAM, None, SensorModel(sample_rate_hz=500.0), seed=5, lead_in_s=1.0
    )
    noise = rec_noisy.accel.astype(float) - rec_clean.accel.astype(float)
    f, psd = welch(noise, fs=500.0, nperseg=2048, axis=0)
    band = (f > 1.0) & (f < 240.0)
    assert_allclose(psd[band].mean(axis=0), d**2, rtol=0.05)


def test_quantisation_and_clipping():
    step = 3.9e-6 * G
    sensor = SensorModel(sample_rate_hz=200.0, resolution_m_s2=step, range_m_s2=0.03)
    rec, _ = simulate_run(PROGRAM, None, sensor, seed=0)
    a = rec.accel.astype(float)
    # x and y: v^2/r = 0.05 m/s^2 is clipped at +-0.03; z (g) at +0.03 too
    assert a.max() == pytest.approx(0.03, rel=1e-7) and a.min() == pytest.approx(-0.03, rel=1e-7)
    assert np.all(np.abs(a) <= np.float32(0.03))
    inside = np.abs(a[:, :2]) < 0.029
    steps = a[:, :2][inside] / step
    assert_allclose(steps, np.round(steps), atol=1e-3)
    assert np.mean(np.abs(a[:, :2]) >= np.float32(0.03)) > 0.1


def test_float32_output_and_gravity_on_z():
    rec, _ = simulate_run(PROGRAM, None, SensorModel(sample_rate_hz=200.0), seed=0)
    assert rec.accel.dtype == np.float32
    assert_allclose(rec.accel[:, 2], G, rtol=1e-7)


def test_reproducible_with_seed():
    sensor = SensorModel(sample_rate_hz=200.0, noise_density_m_s2_rthz=1e-4, flicker_corner_hz=1)
    a1, t1 = simulate_run(PROGRAM, None, sensor, seed=42)
    a2, t2 = simulate_run(PROGRAM, None, sensor, seed=42)
    a3, _ = simulate_run(PROGRAM, None, sensor, seed=43)
    assert np.array_equal(a1.accel, a2.accel) and t1 == t2
    assert not np.array_equal(a1.accel, a3.accel)
    a4, t4 = simulate_run(PROGRAM, None, sensor)
    a5, _ = simulate_run(PROGRAM, None, sensor, seed=t4["seed"])
    assert isinstance(t4["seed"], int) and np.array_equal(a4.accel, a5.accel)


def test_sample_clock_error_stretches_the_period():
    ppm = 1000.0  # exaggerated so that one run resolves it to < 1 %
    sensor = SensorModel(sample_rate_hz=200.0, clock_ppm=ppm)
    program = TestProgram(radius_m=0.05, feed_m_per_s=0.05, cycles_per_direction=6, dwell_s=0.3)
    rec, truth = simulate_run(program, None, sensor, seed=0)
    rec0, truth0 = simulate_run(program, None, SensorModel(sample_rate_hz=200.0), seed=0)
    assert rec.dt_ns == rec0.dt_ns == 5_000_000
    # a block lasts (1 + ppm 1e-6) longer on the sensor's clock
    b, b0 = truth["blocks"][0], truth0["blocks"][0]
    assert_allclose(
        (b["end_s"] - b["start_s"]) / (b0["end_s"] - b0["start_s"]), 1 + ppm * 1e-6, rtol=1e-12
    )
    # the x signal's period, from its phase drift at the nominal frequency
    t = rec.time_s
    omega = program.omega_rad_s
    phases = []
    for start in (b["analysed_start_s"], b["analysed_start_s"] + 5 * program.period_s):
        m = (t >= start) & (t < start + program.period_s)
        design = np.column_stack([np.cos(omega * t[m]), np.sin(omega * t[m]), np.ones(m.sum())])
        (c, s, _), *_ = np.linalg.lstsq(design, rec.accel[m, 0].astype(float), rcond=None)
        phases.append(math.atan2(-s, c))
    # psi drifts by omega (1/(1+e) - 1) per second of sensor time
    drift = math.remainder(phases[1] - phases[0], 2 * math.pi) / (5 * program.period_s)
    period_error = -drift / omega
    assert_allclose(period_error, ppm * 1e-6, rtol=0.01)


def test_thermal_drift_truth_is_the_mean_over_analysed_cycles():
    machine, sensor = with_effects(["sensor_thermal_drift"], None, SensorModel(beta_rad=50e-6))
    assert sensor.beta_0_rad == pytest.approx(250e-6)
    _, truth = simulate_run(PROGRAM, machine, sensor, seed=0, lead_in_s=1.0)
    windows = [(b["analysed_start_s"], b["analysed_end_s"]) for b in truth["blocks"]]
    t = np.concatenate([np.linspace(a, b, 20001) for a, b in windows])
    expected = np.mean(50e-6 + 200e-6 * np.exp(-t / 300.0))
    assert_allclose(truth["sensor_squareness_rad"], expected, rtol=1e-6)
    assert truth["effects"]["sensor_thermal_drift"]["tau_warm_s"] == 300.0


def test_uptime_shifts_the_counter_and_the_warm_up():
    """A board powered 120 s before the first sample: its counter starts at 120 s of
    samples, beta and the temperature are 120 s into their warm-up."""
    machine, sensor = with_effects(["sensor_thermal_drift"], None, SensorModel(beta_rad=50e-6))
    sensor = replace(sensor, sample_rate_hz=200.0, temperature_c=21.0, temperature_rise_c=8.0)
    rec, truth = simulate_run(PROGRAM, machine, sensor, seed=0, lead_in_s=1.0, uptime_s=120.0)
    assert rec.seq[0] == 120 * 200 and truth["uptime_s"] == 120.0
    t = rec.time_s + 120.0
    assert_allclose(rec.temperature_c, 21.0 + 8.0 * (1 - np.exp(-t / 300.0)), atol=0.005)
    windows = [(b["analysed_start_s"], b["analysed_end_s"]) for b in truth["blocks"]]
    t = np.concatenate([np.linspace(a, b, 20001) for a, b in windows]) + 120.0
    expected = np.mean(50e-6 + 200e-6 * np.exp(-t / 300.0))
    assert_allclose(truth["sensor_squareness_rad"], expected, rtol=1e-6)


def test_no_temperature_channel_unless_asked():
    rec, _ = simulate_run(PROGRAM, MachineModel(), SensorModel(sample_rate_hz=200.0), seed=0)
    assert rec.temperature_c is None


def test_gain_and_bias():
    _, sensor = with_effects(["sensor_gain_mismatch"], None, SensorModel(sample_rate_hz=200.0))
    rec, _ = simulate_run(PROGRAM, MachineModel(), sensor, seed=0, lead_in_s=1.0)
    # at rest, before the first block: x, y read the bias; z reads (1 + g_z) g + bias
    rest = rec.accel[:100].astype(float)
    assert_allclose(rest.mean(axis=0), [0.01 * G, -0.005 * G, 1.001 * G + 0.02 * G], rtol=1e-6)


def test_a_sensor_without_drift_senses_as_one_whose_drift_is_nil():
    # the one beta of a sensor without drift against the array of a drift of zero size
    sensor = SensorModel(eps_c_rad=math.radians(2.1), beta_rad=40e-6, tilt_rad=(3e-5, -2e-5))
    rng = np.random.default_rng(3)
    acc, t = rng.normal(0.0, 1.0, (5000, 2)), np.linspace(0.0, 100.0, 5000)
    yaw = rng.normal(0.0, 1e-4, 5000)
    nil = replace(sensor, beta_0_rad=sensor.beta_rad)
    assert_allclose(
        sensor.sense(acc, (0.0, 0.0), yaw, t), nil.sense(acc, (0.0, 0.0), yaw, t), rtol=1e-15
    )
