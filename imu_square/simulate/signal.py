"""The simulator's noise-free reading at any true times, stage by stage.

:func:`~imu_square.simulate.simulate_run` samples the whole test on the
sensor's clock and adds noise; a model fit (``imu_square.discrepancy``)
needs the same physics at the sample times of a recording it compares with,
many times over, often changing one parameter that touches one stage only.
This module is that physics, the chain of ``simulate_run`` cut at its stages
so a caller can keep the ones that did not change:

1. :func:`axis_motion`: one axis's commanded path with its servo lag and the
   drive effects at its reversals (backlash, friction spike, vibration);
2. :meth:`Geometry.apply`: the geometric error map, both axes to the carriage;
3. :func:`sense_motion`: gravity coupling, carriage yaw, the sensor's
   mounting, non-orthogonality, gain and bias.

The three in a row equal ``simulate_run``'s reading before noise, ADC steps
and clipping, sample for sample (``tests/test_simulate_effects.py`` checks).
"""

from imu_square.simulate.drive import add_backlash, add_spikes, add_vibration
from imu_square.simulate.kinematics import (
    carriage_tilt,
    reversal_delays,
    ring_at_block_edges,
    servo_path,
)
from imu_square.simulate.trajectory import build_timeline


def model_timeline(program, machine, lead_in_s=3.0, lead_out_s=3.0):
    """The commanded timeline ``simulate_run`` builds for a program and machine.

    Parameters
    ----------
    program : TestProgram
        The test program.
    machine : MachineModel
        The machine (its feed ramps).
    lead_in_s, lead_out_s : float
        Idle time before the first and after the last block. [s]

    Returns
    -------
    Timeline
    """
    return build_timeline(program, machine.ramp_s, machine.ramp_profile, lead_in_s, lead_out_s)


def axis_parameters(machine, axis):
    """What one axis's motion depends on besides the timeline: a hashable key.

    Parameters
    ----------
    machine : MachineModel
        The machine.
    axis : int
        0 for X, 1 for Y.

    Returns
    -------
    tuple
        Servo lag, backlash, spike and vibration sizes of that axis, the
        shared shapes and the vibration at block starts and ends. [SI]
    """
    m = machine
    own = (
        (m.tau_x_s, m.backlash_x_m, m.spike_x_m_s2, m.vibration_x_m_s2)
        if axis == 0
        else (m.tau_y_s, m.backlash_y_m, m.spike_y_m_s2, m.vibration_y_m_s2)
    )
    return (
        *own,
        m.servo_model,
        m.backlash_take_up_s,
        m.backlash_onset,
        m.spike_tau_s,
        m.spike_onset,
        m.spike_symmetric,
        m.vibration_hz,
        m.vibration_damping,
        m.vibration_start_stop_m_s2,
        m.vibration_start_stop_quadrature_m_s2,
    )


def axis_motion(timeline, machine, t_s, axis):
    """Actual position, velocity and acceleration of one axis, before the geometry.

    Parameters
    ----------
    timeline : Timeline
        The commanded path.
    machine : MachineModel
        The machine.
    t_s : ndarray, shape (n,)
        True times, increasing. [s]
    axis : int
        0 for X, 1 for Y.

    Returns
    -------
    list of 3 ndarray
        [m, m/s, m/s^2]
    """
    params = axis_parameters(machine, axis)
    tau, lost, spike, vibration = params[:4]
    take_up, take_up_onset, spike_tau, onset, symmetric, hz, damping = params[5:12]
    p, delays = servo_path(timeline, t_s, axis, tau, machine.servo_model)
    if lost or spike or vibration:
        times, directions, initial = timeline.reversals(axis)
        times = times + reversal_delays(times, delays)
        add_backlash(p, t_s, times, directions, initial, lost, take_up, take_up_onset)
        add_spikes(p, t_s, times, directions, spike, spike_tau, onset, symmetric)
        add_vibration(p, t_s, times, directions, vibration, hz, damping)
    ring_at_block_edges(p, timeline, t_s, axis, delays, machine)
    return p


def sense_motion(machine, sensor, pos, acc, t_s, power_on_s=0.0):
    """The sensor's reading of a carriage motion.

    Parameters
    ----------
    machine : MachineModel
        The machine (gravity coupling, carriage yaw).
    sensor : SensorModel
        The sensor; its noise, ADC steps and clipping are not applied.
    pos, acc : ndarray, shape (n, 2)
        Carriage position and acceleration in the machine frame. [m, m/s^2]
    t_s : ndarray, shape (n,)
        True times on the timeline. [s]
    power_on_s : float
        The sensor's time since power-on at ``t = 0`` (its warm-up). [s]

    Returns
    -------
    ndarray, shape (n, 3)
        Specific force along the sensor's x, y, z after gain and bias. [m/s^2]
    """
    tilt = carriage_tilt(pos, machine)
    g = machine.geometry
    # without an associated yaw the carriage does not turn: a scalar spares the trigonometry
    yaw = g.carriage_yaw(pos[:, 0], pos[:, 1]) if g.yaw_x or g.yaw_y else 0.0
    return sensor.apply_gain(sensor.sense(acc, tilt, yaw, t_s + power_on_s))
