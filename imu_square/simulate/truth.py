"""The ground truth of a simulated run, as written to ``run.truth.json``.

Angles in radians, times on the recording's (sensor's) clock. Quantities that
drift (squareness drift, the sensor's warm-up) are time means over the
analysed whole cycles of all blocks, which is what a fit over those cycles
measures to first order.

Keys (the table "Quantity names" in ``docs/model.md`` lists them all):

- ``machine_squareness_rad``: the machine's squareness alpha (E_C0X);
  ``sensor_squareness_rad``: the sensor's non-orthogonality beta (E_SC0X);
  ``squareness_rad = alpha + beta``, the global measurand (paper Eq. 4). It
  is what ``theta_y - theta_x`` measures only on a machine without
  straightness errors or gravity coupling and a sensor square to the axes, see
  ``expected_squareness_rad``;
- ``local_machine_squareness_rad``: the squareness a ballbar sees on this
  circle, from the geometry alone (straightness/yaw included, sensor excluded);
- ``expected_squareness_rad``: what ``theta_y - theta_x`` (mean of CCW and
  flipped CW) should read on this run: the local Jacobian ``J`` of the error
  map and the gravity coupling ``K`` act on the commanded acceleration as
  ``M = I + J - (g r / A) K``, the sensor turns it by ``-(eps_c +
  carriage_yaw)`` and leans its y axis by ``beta``, and the thetas are read
  off exactly (``alpha`` shows as ``alpha cos(2 eps_c)``); the harmonics of a
  quartic X form (Chapman's machine 7, :meth:`Geometry.circle_squareness`)
  enter as a shear, as the squareness does;
- ``eps_c_rad``: sensor mounting rotation; ``carriage_yaw_rad``: the
  carriage's yaw at the circle centre (associated yaw), which adds to it;
- ``servo_mismatch_rad``: the servos' phase mismatch on the circle,
  ``omega (tau_y - tau_x)`` for pure lags, ``atan(omega tau_y) - atan(omega
  tau_x)`` for first-order servos;
- ``servo_amplitude_phase_rad``: the apparent ``theta_y - theta_x`` that
  first-order servos add by shrinking each axis's amplitude by its own
  ``1 / sqrt(1 + (omega tau)^2)``, seen through sensor axes turned by
  ``eps_c``: about ``(A_x - A_y) / A sin(2 eps_c)``, the same in both
  directions (0 for pure lags); included in ``expected_squareness_rad``;
- ``gravity_phase_rad``: the apparent ``theta_y - theta_x`` that gravity
  coupling adds (position-angle domain, the same in both directions);
- ``expected_squareness_gravity_free_rad``: ``expected_squareness_rad``
  without the gravity coupling, what a fit over two feeds reads
  (``analyze --separate-gravity``); ``gravity_coupling_rad_per_m``: the
  coupling that shows in ``theta_y - theta_x``
  (:func:`gravity_coupling_rad_per_m`);
- ``feeds``: per feed, in the program's order, ``feed_mm_per_min``,
  ``omega_rad_s``, ``amplitude_m_s2``, ``servo_mismatch_rad``,
  ``servo_amplitude_phase_rad``, ``gravity_phase_rad`` and
  ``expected_squareness_rad``; the top-level keys
  of the same names are the first feed's;
- ``omega_rad_s``, ``amplitude_m_s2 = v^2/r``, ``sample_rate_hz``,
  ``clock_ppm``, ``noise_density_m_s2_rthz``, ``ramp_s``, ``ramp_profile``
  (on a controller's motion: the mean time its blocks took from rest to
  cruise, and ``"sampled"``); the feed-dependent keys are those of the feed
  the axes ran, which a controller may hold below the program's;
- ``motion``: where the commanded motion came from: ``{"source":
  "imu-square trajectory", "ramp_s", "ramp_profile"}``, or a controller's
  (:class:`~imu_square.simulate.sampled_motion.SampledMotion`: its name and
  version, its configuration, the NC program's digest, the feeds as run and
  each block's ramp);
- ``effects``: the named effects that are on, with their parameters (SI);
- ``seed``, ``program`` (file units), ``n_samples``, ``t0_ns``, ``uptime_s`` (the
  sensor's time since power-on at the first sample);
- ``blocks``: per block ``index``, ``direction``, the start and end of the
  commanded motion (each actual axis follows its servo lag ``tau`` later)
  as ``start_ns`` / ``end_ns`` (recording clock) and ``start_s`` / ``end_s``
  from the first sample, ``analysed_start_s`` / ``analysed_end_s`` (the whole cycles
  between the overshoots), and ``feed``, the index of the block's feed;
- ``reversal_times_s``: ``{"x": [...], "y": [...]}``, when each actual axis
  reverses (servo lag included), from the first sample;
- ``alpha_rad``, ``beta_rad``, ``local_squareness_rad``,
  ``expected_theta_diff_exact_rad`` and ``expected_theta_diff_rad``: an earlier
  release's names, written until the next release.
"""

import math
from dataclasses import replace

import numpy as np

from imu_square.simulate.kinematics import servo_response
from imu_square.units import G


def _gravity_phases(program, machine):
    """Apparent theta_x, theta_y from the position-dependent tilt (position-angle domain)."""
    kxx, kxy, kyx, kyy = machine.tilt_per_m
    r, a = program.radius_m, program.centripetal_m_s2
    theta_x = -math.atan2(G * kxy * r, a - G * kxx * r)
    theta_y = math.atan2(G * kyx * r, a - G * kyy * r)
    return theta_x, theta_y


def servo_gains(machine, omega_rad_s):
    """Each axis's amplitude gain through its servo on the circle (1 for pure lags)."""
    return tuple(
        servo_response(omega_rad_s, tau, machine.servo_model)[0]
        for tau in (machine.tau_x_s, machine.tau_y_s)
    )


def _exact_theta_diff(program, machine, alpha_beta_t, eps, harmonics, gains=(1.0, 1.0)):
    """``theta_y - theta_x`` of the linearised circle, exact in the rotation ``eps``.

    ``harmonics`` (circle minus local squareness) enters as a shear, as the
    squareness does; ``gains`` are the axes' servo amplitude gains.
    """
    beta, t_mean = alpha_beta_t
    cx, cy = program.centre_m
    jxx, jxy, jyx, jyy = (float(v) for v in machine.geometry.jacobian(cx, cy, t_mean))
    jxy -= harmonics
    kxx, kxy, kyx, kyy = machine.tilt_per_m
    q = G * program.radius_m / program.centripetal_m_s2
    m = np.array([[1.0 + jxx - q * kxx, jxy - q * kxy], [jyx - q * kyx, 1.0 + jyy - q * kyy]])
    m = m @ np.diag(gains)  # each axis's servo scales its own motion
    c, s = math.cos(eps), math.sin(eps)
    n = np.array([[c, s], [-s, c]]) @ m
    ny = -math.sin(beta) * n[0] + math.cos(beta) * n[1]
    diff = math.atan2(-ny[0], ny[1]) - math.atan2(n[0, 1], n[0, 0])
    return math.remainder(diff, 2 * math.pi)  # both phases can straddle +-pi


def gravity_coupling_rad_per_m(machine, eps_rad):
    """The gravity coupling that shows in ``theta_y - theta_x``, per metre of radius.

    To first order, gravity coupling ``K`` (``machine.tilt_per_m``) seen through
    a sensor turned by ``eps`` adds ``(g r / A) kappa`` to ``theta_y - theta_x``
    with ``kappa = cos(2 eps) (k_xy + k_yx) + sin(2 eps) (k_yy - k_xx)``: the
    symmetric shear of the tilt gradient in the sensor's axes, as a squareness
    shows as ``alpha cos(2 eps)``.

    Parameters
    ----------
    machine : MachineModel
        The machine (its ``tilt_per_m``).
    eps_rad : float
        Rotation of the sensor's axes from the machine's (mounting plus
        carriage yaw). [rad]

    Returns
    -------
    float
        ``kappa``. [rad/m]
    """
    kxx, kxy, kyx, kyy = machine.tilt_per_m
    return math.cos(2 * eps_rad) * (kxy + kyx) + math.sin(2 * eps_rad) * (kyy - kxx)


def _feed_truth(program, machine, beta_t, eps, harmonics):
    """The quantities that depend on the feed, for a one-feed program."""
    theta_gx, theta_gy = _gravity_phases(program, machine)
    omega = program.omega_rad_s
    delay_x, delay_y = (
        servo_response(omega, tau, machine.servo_model)[1]
        for tau in (machine.tau_x_s, machine.tau_y_s)
    )
    expected = _exact_theta_diff(
        program, machine, beta_t, eps, harmonics, servo_gains(machine, omega)
    )
    without = _exact_theta_diff(program, machine, beta_t, eps, harmonics)
    return {
        "feed_mm_per_min": program.feed_m_per_s * 6e4,
        "omega_rad_s": omega,
        "amplitude_m_s2": program.centripetal_m_s2,
        "servo_mismatch_rad": omega * (delay_y - delay_x),
        "servo_amplitude_phase_rad": expected - without,
        "gravity_phase_rad": theta_gy - theta_gx,
        "expected_squareness_rad": expected + 0.0,
    }


def _servo_delay_at(timeline, t_s, tau_s, model):
    """The servo's delay on the block that holds ``t_s`` (its feed sets it). [s]"""
    block = next((b for b in timeline.blocks if t_s <= b.t_end_s), timeline.blocks[-1])
    return servo_response(block.omega_rad_s, tau_s, model)[1]


def trajectory_source(machine):
    """The truth's ``motion`` entry for our own trajectory.

    Parameters
    ----------
    machine : MachineModel
        The machine (its feed ramps).

    Returns
    -------
    dict
    """
    return {
        "source": "imu-square trajectory",
        "ramp_s": machine.ramp_s,
        "ramp_profile": machine.ramp_profile,
    }


def build_truth(
    program,
    machine,
    sensor,
    timeline,
    seed,
    clock_factor,
    t0_ns,
    uptime_s=0.0,
    run_program=None,
):
    """The truth dictionary of one run.

    Parameters
    ----------
    program : TestProgram
        The program that ran.
    machine : MachineModel
        The machine.
    sensor : SensorModel
        The sensor.
    timeline : Timeline or SampledMotion
        The commanded motion of the run.
    seed : int
        Seed of the noise.
    clock_factor : float
        Sensor clock time per true time, ``1 + ppm * 1e-6``.
    t0_ns : int
        Recording time of the first sample. [ns]
    uptime_s : float
        The sensor's time since power-on at the first sample (thermal drift). [s]
    run_program : TestProgram, optional
        The program at the feeds the axes ran (a controller may run an arc
        slower than programmed); ``program`` if None.

    Returns
    -------
    dict
        JSON-serialisable.
    """
    geometry = machine.geometry
    windows = timeline.analysed_windows()
    durations = np.array([b - a for a, b in windows])
    mids = np.array([0.5 * (a + b) for a, b in windows])
    t_mean = float(np.sum(mids * durations) / np.sum(durations))
    alpha = float(geometry.machine_squareness_at(t_mean))
    beta = float(
        sum(sensor.mean_beta(a + uptime_s, b + uptime_s) * (b - a) for a, b in windows)
        / float(np.sum(durations))
    )
    cx, cy = program.centre_m
    blocks = []
    plans = program.blocks()
    for b, (a0, a1), plan in zip(timeline.blocks, windows, plans, strict=True):
        start, end = b.t_start_s * clock_factor, b.t_end_s * clock_factor
        blocks.append(
            {
                "index": b.index,
                "direction": b.direction,
                "start_ns": t0_ns + round(start * 1e9),
                "end_ns": t0_ns + round(end * 1e9),
                "start_s": start,
                "end_s": end,
                "analysed_start_s": a0 * clock_factor,
                "analysed_end_s": a1 * clock_factor,
                "feed": plan.feed,
            }
        )
    effects = {**machine.effects(), **sensor.effects()}
    reversals = {}
    for axis, name, tau in ((0, "x", machine.tau_x_s), (1, "y", machine.tau_y_s)):
        times, _, _ = timeline.reversals(axis)
        reversals[name] = [
            (t + _servo_delay_at(timeline, t, tau, machine.servo_model)) * clock_factor
            for t in times
        ]
    local = float(geometry.local_machine_squareness(cx, cy, t_mean)) + 0.0
    circle = float(geometry.circle_squareness(cx, cy, program.radius_m, t_mean)) + 0.0
    yaw = float(geometry.carriage_yaw(cx, cy))
    eps = sensor.eps_c_rad + yaw
    harmonics = circle - local
    run = program if run_program is None else run_program
    feeds = [
        _feed_truth(run.at_feed(f), machine, (beta, t_mean), eps, harmonics)
        for f in range(program.n_feeds)
    ]
    first = feeds[0]
    expected = first["expected_squareness_rad"]
    level = replace(machine, tilt_per_m=(0.0, 0.0, 0.0, 0.0))
    gravity_free = (
        _exact_theta_diff(
            run.at_feed(0),
            level,
            (beta, t_mean),
            eps,
            harmonics,
            servo_gains(machine, first["omega_rad_s"]),
        )
        + 0.0
    )
    return {
        "machine_squareness_rad": alpha,
        "sensor_squareness_rad": beta,
        "squareness_rad": alpha + beta,
        "local_machine_squareness_rad": local,
        "expected_squareness_rad": expected,
        "eps_c_rad": sensor.eps_c_rad,
        "carriage_yaw_rad": yaw,
        "expected_squareness_gravity_free_rad": gravity_free,
        "gravity_coupling_rad_per_m": gravity_coupling_rad_per_m(machine, eps),
        "servo_mismatch_rad": first["servo_mismatch_rad"],
        "servo_amplitude_phase_rad": first["servo_amplitude_phase_rad"],
        "gravity_phase_rad": first["gravity_phase_rad"],
        "omega_rad_s": first["omega_rad_s"],
        "amplitude_m_s2": first["amplitude_m_s2"],
        "feeds": feeds,
        "sample_rate_hz": sensor.sample_rate_hz,
        "clock_ppm": sensor.clock_ppm,
        "noise_density_m_s2_rthz": sensor.noise_density_m_s2_rthz,
        "ramp_s": machine.ramp_s,
        "ramp_profile": machine.ramp_profile,
        "effects": effects,
        "seed": seed,
        "uptime_s": uptime_s,
        "program": program.to_mapping(),
        "blocks": blocks,
        "reversal_times_s": reversals,
        # An earlier release's names, written for one release more: machine_squareness_rad,
        # sensor_squareness_rad, local_machine_squareness_rad, expected_squareness_rad, and
        # its first-order form, which keeps its old value.
        "alpha_rad": alpha,
        "beta_rad": beta,
        "local_squareness_rad": local,
        "expected_theta_diff_exact_rad": expected,
        "expected_theta_diff_rad": circle + beta + first["gravity_phase_rad"],
    }
