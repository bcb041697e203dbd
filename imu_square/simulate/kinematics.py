"""The carriage's actual motion: commanded path -> servo -> drive effects -> geometry.

Each axis follows its commanded path through its servo, plus the backlash,
friction bump and vibration started at its reversals (which happen when the
servo has carried the commanded reversal through). The geometric error map
then turns the axis positions into the actual carriage position. Position,
velocity and acceleration are carried exactly through every step; nothing is
differenced.

Servo models (``MachineModel.servo_model``), with time constant ``tau`` per axis:

- ``"pure_lag"``: the axis is the command ``tau`` late, ``e^(-s tau)``; the
  circle keeps its amplitude;
- ``"first_order"``: a position loop of gain ``1/tau`` without feed-forward,
  ``1 / (1 + s tau)``. On the circle of angular speed ``omega`` its steady
  response is the command, about the circle's centre, scaled by
  ``1 / sqrt(1 + (omega tau)^2)`` and ``atan(omega tau) / omega`` late: the
  two axes' amplitudes differ at second order in ``omega tau``, which pure
  lags never do. The steady response is applied to each block with its own
  ``omega`` (ramps and dwells included), so the ramps lack the first-order
  transient, a few ``tau`` long, and the carriage at rest sits ``(1 - gain)``
  of the radius off its command towards the centre; neither reaches the
  analysed cycles.
"""

import math

import numpy as np

from imu_square.simulate.drive import (
    add_backlash,
    add_spikes,
    add_start_stop_vibration,
    add_vibration,
)

SERVO_MODELS = ("pure_lag", "first_order")


def servo_response(omega_rad_s, tau_s, model):
    """Steady gain and delay of one axis's servo on a circle.

    Parameters
    ----------
    omega_rad_s : float
        Angular speed of the circle. [rad/s]
    tau_s : float
        The axis's servo time constant (pure lag: the lag). [s]
    model : {"pure_lag", "first_order"}
        The servo model (module docstring).

    Returns
    -------
    gain : float
        Amplitude of the actual over the commanded circle.
    delay_s : float
        Phase lag over ``omega``. [s]
    """
    if model == "pure_lag" or tau_s == 0 or omega_rad_s == 0:
        return 1.0, tau_s
    x = omega_rad_s * tau_s
    return 1.0 / math.sqrt(1.0 + x * x), math.atan(x) / omega_rad_s


def servo_path(timeline, t, axis, tau, model):
    """Commanded axis path through the servo, and the delay of each block's span."""
    if model == "pure_lag":
        return list(timeline.axis_path(t - tau, axis)), [(0.0, tau)]
    centre = timeline.centre_m[axis]
    p = [np.empty_like(t), np.empty_like(t), np.empty_like(t)]
    # Each block's response holds from its start until the next block starts.
    starts = [b.t_start_s for b in timeline.blocks[1:]]
    edges = np.searchsorted(t, starts)
    delays = []
    for b, lo, hi in zip(timeline.blocks, [0, *edges], [*edges, t.size], strict=True):
        gain, delay = servo_response(b.omega_rad_s, tau, model)
        pos, vel, acc = timeline.axis_path(t[lo:hi] - delay, axis)
        p[0][lo:hi] = centre + gain * (pos - centre)
        p[1][lo:hi] = gain * vel
        p[2][lo:hi] = gain * acc
        delays.append((b.t_start_s, delay))
    return p, delays


def reversal_delays(times, delays):
    """Delay of each reversal: that of the block span it falls in. [s]"""
    starts = np.array([s for s, _ in delays])
    k = np.clip(np.searchsorted(starts, times, side="right") - 1, 0, len(delays) - 1)
    return np.array([d for _, d in delays])[k] if len(times) else np.asarray(times)


def block_edges(timeline, axis):
    """The corners of each block's feed ramps, and the axis's share of the acceleration step there.

    A feed ramp steps the acceleration along the direction of motion at its
    corners: up at the start of motion, back down at the end of the start
    ramp, down at the start of the stop ramp and back up at the end of motion
    (the trapezoid's steps; the stop ramp is taken as long as the start's).

    Parameters
    ----------
    timeline : Timeline or SampledMotion
        The commanded path.
    axis : int
        0 for X, 1 for Y.

    Returns
    -------
    times : ndarray, shape (4 * n_blocks,)
        The corners, in time order. [s]
    components : ndarray, shape (4 * n_blocks,)
        The sign of the step (+1 up along the motion, -1 down) times the
        axis's component of the unit direction of motion there,
        ``sign * (-sin phi, cos phi)`` at the position angle ``phi``.
    """
    times, components = [], []
    for b in timeline.blocks:
        phi_end = b.start_angle_rad + b.sign * b.angle_rad
        ramp_angle = b.sign * 0.5 * b.omega_rad_s * b.ramp_s  # travelled in a ramp
        corners = (
            (b.t_start_s, b.start_angle_rad, 1.0),
            (b.t_start_s + b.ramp_s, b.start_angle_rad + ramp_angle, -1.0),
            (b.t_end_s - b.ramp_s, phi_end - ramp_angle, -1.0),
            (b.t_end_s, phi_end, 1.0),
        )
        for tk, phi, step in corners:
            times.append(tk)
            components.append(step * b.sign * (-math.sin(phi) if axis == 0 else math.cos(phi)))
    return np.array(times), np.array(components)


def ring_at_block_edges(p, timeline, t, axis, delays, machine):
    """Add the structural mode rung at the corners of the feed ramps, in place.

    Parameters
    ----------
    p : list of 3 ndarray
        Axis position, velocity, acceleration after the servo, modified in place.
    timeline : Timeline or SampledMotion
        The commanded path.
    t : ndarray, shape (n,)
        True times, increasing. [s]
    axis : int
        0 for X, 1 for Y.
    delays : list of tuple
        The servo's delay of each block span (:func:`servo_path`).
    machine : MachineModel
        The machine (``vibration_start_stop_m_s2`` and its quadrature, the mode's
        frequency and damping).
    """
    m = machine
    if not (m.vibration_start_stop_m_s2 or m.vibration_start_stop_quadrature_m_s2):
        return
    times, components = block_edges(timeline, axis)
    times = times + reversal_delays(times, delays)
    add_start_stop_vibration(
        p,
        t,
        times,
        components,
        m.vibration_start_stop_m_s2,
        m.vibration_hz,
        m.vibration_damping,
        m.vibration_start_stop_quadrature_m_s2,
    )


def carriage_motion(timeline, machine, t):
    """Actual position, velocity and acceleration of the carriage.

    Parameters
    ----------
    timeline : Timeline
        The commanded path.
    machine : MachineModel
        The machine.
    t : ndarray, shape (n,)
        True times from the first sample, increasing. [s]

    Returns
    -------
    pos, vel, acc : ndarray, shape (n, 2)
        In the machine frame. [m, m/s, m/s^2]
    """
    m = machine
    per_axis = (
        (m.tau_x_s, m.backlash_x_m, m.spike_x_m_s2, m.vibration_x_m_s2),
        (m.tau_y_s, m.backlash_y_m, m.spike_y_m_s2, m.vibration_y_m_s2),
    )
    paths = []
    for axis, (tau, lost, spike, vibration) in enumerate(per_axis):
        p, delays = servo_path(timeline, t, axis, tau, m.servo_model)
        if lost or spike or vibration:
            times, directions, initial = timeline.reversals(axis)
            times = times + reversal_delays(times, delays)
            add_backlash(
                p, t, times, directions, initial, lost, m.backlash_take_up_s, m.backlash_onset
            )
            add_spikes(
                p, t, times, directions, spike, m.spike_tau_s, m.spike_onset, m.spike_symmetric
            )
            add_vibration(p, t, times, directions, vibration, m.vibration_hz, m.vibration_damping)
        ring_at_block_edges(p, timeline, t, axis, delays, m)
        paths.append(p)
    return m.geometry.apply(paths[0], paths[1], t)


def carriage_tilt(pos, machine):
    """Tilt of the carriage seen by the x and y channels (gravity coupling).

    Linear in the position from the middle of the axis travels.

    Parameters
    ----------
    pos : ndarray, shape (n, 2)
        Carriage position. [m]
    machine : MachineModel
        The machine (its ``tilt_per_m``).

    Returns
    -------
    tilt_x, tilt_y : ndarray or float
        [rad]
    """
    kxx, kxy, kyx, kyy = machine.tilt_per_m
    if not (kxx or kxy or kyx or kyy):
        return 0.0, 0.0
    x0, y0 = machine.geometry.axis_centre_m
    X = pos[:, 0] - x0
    Y = pos[:, 1] - y0
    return kxx * X + kxy * Y, kyx * X + kyy * Y
