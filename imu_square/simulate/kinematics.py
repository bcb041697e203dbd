"""The carriage's actual motion: commanded path -> servo lag -> drive effects -> geometry.

Each axis follows its commanded path a pure time lag ``tau`` late, plus the
backlash, friction bump and vibration started at its reversals (which happen
``tau`` after the commanded reversals). The geometric error map then turns the
axis positions into the actual carriage position. Position, velocity and
acceleration are carried exactly through every step; nothing is differenced.
"""

from imu_square.simulate.drive import add_backlash, add_spikes, add_vibration


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
        p = list(timeline.axis_path(t - tau, axis))
        if lost or spike or vibration:
            times, directions, initial = timeline.reversals(axis)
            times = times + tau
            add_backlash(p, t, times, directions, initial, lost, m.backlash_take_up_s)
            add_spikes(p, t, times, directions, spike, m.spike_tau_s)
            add_vibration(p, t, times, directions, vibration, m.vibration_hz, m.vibration_damping)
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
