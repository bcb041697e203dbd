"""Zero-phase low-pass: symmetric impulse response, no phase, |H|^2 response."""

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy import signal

from imu_square.errors import AnalysisError
from imu_square.pipeline.filter import (
    design_lowpass,
    lowpass,
    settling_time_s,
)

FS = 1000.0


@pytest.mark.parametrize("order", [1, 2, 4])
def test_impulse_response_symmetric_and_peak_unmoved(order):
    x = np.zeros(4001)
    x[2000] = 1.0
    y = lowpass(x, 4.0, order, FS)
    assert int(np.argmax(y)) == 2000
    # Equal up to the edge padding, which differs at 1e-8 of the peak for order 4.
    assert_allclose(y[:2000], y[2001:][::-1], atol=1e-8 * y.max())


def test_no_phase_at_circle_frequency():
    # The paper's test: v = 0.1 m/s on r = 0.1 m, omega = 1 rad/s.
    f0 = 1 / (2 * np.pi)
    t = np.arange(int(200 * FS)) / FS
    x = np.cos(2 * np.pi * f0 * t + 0.3)
    y = lowpass(x, 4.0, 1, FS)
    core = slice(int(20 * FS), int(180 * FS))  # whole cycles away from the edges
    z = np.exp(-2j * np.pi * f0 * t[core])
    phase_in = np.angle(np.sum(x[core] * z))
    phase_out = np.angle(np.sum(y[core] * z))
    assert abs(phase_out - phase_in) < 1e-9
    # Amplitude follows the forward-backward response |H|^2.
    _, h = signal.sosfreqz(design_lowpass(4.0, 1, FS), worN=[f0], fs=FS)
    gain = abs(np.sum(y[core] * z)) / abs(np.sum(x[core] * z))
    assert_allclose(gain, abs(h[0]) ** 2, rtol=1e-6)


def test_first_order_means_half_gain_at_cutoff_after_forward_backward():
    t = np.arange(int(20 * FS)) / FS
    x = np.sin(2 * np.pi * 4.0 * t)
    y = lowpass(x, 4.0, 1, FS)
    core = slice(int(5 * FS), int(15 * FS))
    assert_allclose(np.std(y[core]) / np.std(x[core]), 0.5, rtol=2e-3)


def test_breaks_stop_the_filter_at_gaps():
    x = np.concatenate([np.zeros(3000), np.ones(3000)])
    y = lowpass(x, 4.0, 1, FS, breaks=[3000])
    assert_allclose(y, x, atol=1e-12)
    smeared = lowpass(x, 4.0, 1, FS)
    assert abs(smeared[2990]) > 0.1


def test_settling_time_bounds_the_impulse_response():
    x = np.zeros(8001)
    x[4000] = 1.0
    y = lowpass(x, 4.0, 1, FS)
    half = int(settling_time_s(4.0, 1) * FS)
    assert np.max(np.abs(y[4000 + half :])) < 2e-3 * y.max()


def test_bad_cutoff_and_order_are_refused():
    with pytest.raises(AnalysisError, match=r"cutoff_hz must be in \(0, 500\).*600"):
        design_lowpass(600.0, 1, FS)
    with pytest.raises(AnalysisError, match=r"filter order must be a whole number.*0"):
        design_lowpass(4.0, 0, FS)
