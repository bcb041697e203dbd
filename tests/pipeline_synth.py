"""Closed-form circle recordings for the pipeline tests (independent of the simulator).

The commanded position angle of each block follows a trapezoidal speed
profile (linear ramps of ``ramp_s``); accelerations are analytic. Effects
follow ``docs/model.md``: machine squareness ``alpha`` (x -> x - y alpha),
per-axis time lags, sensor rotation ``eps_c`` (a_s = R(-eps_c) a) and sensor
non-orthogonality ``beta``; white noise of density ``d`` per axis.
"""

import numpy as np

from imu_square.io.recording import Event, Recording, SensorInfo
from imu_square.program import TestProgram
from imu_square.units import G


def _angle(program, block, t, ramp_s):
    """Commanded angle, speed and acceleration of ``block`` at absolute times ``t``."""
    w = program.omega_rad_s
    total = program.block_angle_rad
    dur = total / w + ramp_s
    tau = np.clip(t - block["t0"], 0.0, dur)
    up = tau < ramp_s
    down = tau > dur - ramp_s
    cruise = w * ramp_s / 2 + w * (tau - ramp_s)
    phi = np.where(up, w * tau**2 / (2 * ramp_s), cruise)
    phi = np.where(down, total - w * (dur - tau) ** 2 / (2 * ramp_s), phi)
    dphi = np.where(up, w * tau / ramp_s, np.where(down, w * (dur - tau) / ramp_s, w))
    ddphi = np.where(up, w / ramp_s, np.where(down, -w / ramp_s, 0.0))
    s = block["sign"]
    return block["start"] + s * phi, s * dphi, s * ddphi


def synth_circle(
    program=None,
    *,
    alpha=0.0,
    beta=0.0,
    eps_c=0.0,
    tau_x=0.0,
    tau_y=0.0,
    ramp_s=0.5,
    density=0.0,
    fs=200.0,
    lead_s=3.0,
    seed=0,
    scale=1.0,
    sensor=None,
    events=False,
):
    """A recording of ``program`` with the named effects, and its block timeline.

    Returns
    -------
    Recording, dict
        The recording (sensor frame, m/s^2 times ``scale``) and the truth:
        ``squareness_rad``, ``servo_mismatch_rad``, ``eps_c_rad``, ``blocks``.
    """
    prog = program or TestProgram(cycles_per_direction=4, dwell_s=1.0)
    w = prog.omega_rad_s
    dur = prog.block_angle_rad / w + ramp_s
    blocks = []
    t0 = lead_s
    angle = prog.start_angle_rad
    for _ in range(prog.runs):
        for d in prog.order:
            sign = 1 if d == "ccw" else -1
            blocks.append({"t0": t0, "t1": t0 + dur, "sign": sign, "start": angle, "dir": d})
            angle += sign * prog.block_angle_rad
            t0 += dur + prog.dwell_s
    t_end = blocks[-1]["t1"] + lead_s
    n = int(t_end * fs)
    t = np.arange(n) / fs
    r = prog.radius_m

    def axis_accel(t_eval, which):
        acc = np.zeros_like(t_eval)
        for b in blocks:
            phi, dphi, ddphi = _angle(prog, b, t_eval, ramp_s)
            inside = (t_eval >= b["t0"]) & (t_eval <= b["t1"])
            if which == "x":
                a = -r * (dphi**2 * np.cos(phi) + ddphi * np.sin(phi))
            else:
                a = -r * (dphi**2 * np.sin(phi) - ddphi * np.cos(phi))
            acc = acc + np.where(inside, a, 0.0)
        return acc

    ax = axis_accel(t - tau_x, "x")
    ay = axis_accel(t - tau_y, "y")
    a_mx = ax - alpha * ay  # machine squareness: x -> x - y alpha
    a_my = ay
    sx = np.cos(eps_c) * a_mx + np.sin(eps_c) * a_my  # a_s = R(-eps_c) a
    sy = -np.sin(eps_c) * a_mx + np.cos(eps_c) * a_my
    sy = -np.sin(beta) * sx + np.cos(beta) * sy
    acc = np.column_stack([sx, sy, np.full(n, G)])
    rng = np.random.default_rng(seed)
    acc = acc + rng.normal(0.0, density * np.sqrt(fs / 2), acc.shape)
    dt_ns = round(1e9 / fs)
    ev = []
    if events:
        for i, b in enumerate(blocks):
            ev.append(Event(int(b["t0"] * 1e9), "block_start", b["dir"], i))
            ev.append(Event(int(b["t1"] * 1e9), "block_end", b["dir"], i))
    rec = Recording(
        accel=acc * scale,
        time_ns=np.arange(n, dtype=np.int64) * dt_ns,
        seq=np.arange(n),
        dt_ns=dt_ns,
        program=prog,
        sensor=sensor or SensorInfo(noise_density_m_s2_rthz=density),
        events=ev,
        metadata={"producer": "tests/pipeline_synth.py"},
    )
    truth = {
        "squareness_rad": alpha + beta,
        "servo_mismatch_rad": w * (tau_y - tau_x),
        "eps_c_rad": eps_c,
        "blocks": blocks,
    }
    return rec, truth
