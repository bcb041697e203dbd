"""Flip and average: geometry is the same in both directions, lags flip sign."""

import numpy as np
from numpy.testing import assert_allclose
from pipeline_synth import synth_circle

from imu_square.pipeline.align import cycle_traces
from imu_square.pipeline.filter import lowpass
from imu_square.pipeline.segment import segment
from imu_square.program import TestProgram

PROG = TestProgram(cycles_per_direction=3, dwell_s=1.0)


def _traces(rec, bad=(), grid_points=256):
    xy = lowpass(rec.accel[:, :2], 4.0, 1, rec.sample_rate_hz)
    seg = segment(rec.time_s, xy, rec.program)
    return cycle_traces(rec.time_s, xy, seg, bad, 0.3, grid_points)


def _phases(c, phi):
    """theta_x, theta_y of the mean traces by projection on the fundamental. [rad]"""
    z = np.exp(-1j * phi)
    # sum over phi of cos(phi - psi) exp(-i phi) is proportional to exp(-i psi).
    theta_x = -np.angle(np.sum(-c.x.mean(axis=0) * z))
    theta_y = -np.angle(np.sum(-c.y.mean(axis=0) * z)) - np.pi / 2  # -a_y = A cos(phi - th - pi/2)
    return theta_x, np.angle(np.exp(1j * theta_y))


def test_flipped_cw_matches_ccw_for_geometry():
    alpha = 300e-6
    rec, _ = synth_circle(PROG, alpha=alpha, fs=500.0)
    cyc = _traces(rec)
    assert cyc.ccw.n == 3 and cyc.cw.n == 3
    assert_allclose(cyc.phi_grid[[0, -1]], [np.pi / 256, 2 * np.pi - np.pi / 256])
    # Ideal circle on the grid: a_x = -A cos(phi), times the filter's |H|^2 at omega.
    gain = 1 / (1 + (1 / (2 * np.pi) / 4.0) ** 2)
    for c in (cyc.ccw, cyc.cw):
        assert_allclose(
            c.x, np.broadcast_to(-0.1 * gain * np.cos(cyc.phi_grid), c.x.shape), atol=1e-4
        )
    # Same position -> same geometry in both directions: theta_y - theta_x = alpha.
    # The common phase of each direction is set by its anchor, which the sampling
    # grid (2 ms here) quantises: omega * dt.
    tx_ccw, ty_ccw = _phases(cyc.ccw, cyc.phi_grid)
    tx_cw, ty_cw = _phases(cyc.cw, cyc.phi_grid)
    assert_allclose([ty_ccw - tx_ccw, ty_cw - tx_cw], alpha, atol=1e-7)
    assert abs(tx_ccw - tx_cw) < PROG.omega_rad_s * 2e-3
    # Pairs: k-th cycle in time of each direction.
    assert list(cyc.ccw.pair) == [0, 1, 2] and list(cyc.cw.pair) == [0, 1, 2]
    assert np.all(np.diff(cyc.cw.t_start_s) > 0)


def test_servo_mismatch_flips_sign_with_the_direction():
    tau_x, tau_y = 1e-3, 3e-3  # m = omega (tau_y - tau_x) = 2e-3 rad
    rec, truth = synth_circle(PROG, tau_x=tau_x, tau_y=tau_y, fs=500.0)
    cyc = _traces(rec)
    tx_ccw, ty_ccw = _phases(cyc.ccw, cyc.phi_grid)
    tx_cw, ty_cw = _phases(cyc.cw, cyc.phi_grid)
    m = truth["servo_mismatch_rad"]
    assert_allclose(ty_ccw - tx_ccw, +m, rtol=1e-3)
    assert_allclose(ty_cw - tx_cw, -m, rtol=1e-3)


def test_bad_samples_drop_whole_cycles():
    rec, truth = synth_circle(PROG, fs=200.0)
    b = truth["blocks"][1]
    # Middle of the CW block's middle analysed cycle.
    t_bad = 0.5 * (b["t0"] + b["t1"])
    cyc = _traces(rec, bad=[(t_bad, t_bad)])
    assert cyc.ccw.n == 3 and cyc.cw.n == 2
    assert cyc.dropped == (
        {"direction": "cw", "block": 1, "cycle": 1, "reason": "gap or clipping"},
    )


def test_a_gap_longer_than_a_cycle_drops_every_cycle_it_touches():
    rec, truth = synth_circle(PROG, fs=200.0)
    b = truth["blocks"][0]
    period = PROG.period_s
    # Data missing from 0.6 to 2.1 periods into the analysed cycles: the gap's
    # midpoint lies in cycle 1 only, but cycles 0 and 2 hold its ends.
    start = b["t0"] + PROG.overshoot_rad / PROG.omega_rad_s + 0.6 * period
    cyc = _traces(rec, bad=[(start, start + 1.5 * period)])
    assert cyc.ccw.n == 0 and cyc.cw.n == 3
    assert {d["cycle"] for d in cyc.dropped if d["direction"] == "ccw"} == {0, 1, 2}
