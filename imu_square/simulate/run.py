"""Simulate one circle test: program + machine + sensor -> Recording and its truth.

The sensor's clock is the recording's clock: samples are ``dt`` apart on it,
and when it runs ``ppm`` fast the true time of sample ``i`` is
``i dt / (1 + ppm 1e-6)``. Events and the truth's block times are given on the
recording's clock too.
"""

import math
import secrets

import numpy as np

from imu_square.errors import ConfigError, ControllerError
from imu_square.io.recording import Event, Recording, SensorInfo
from imu_square.simulate.kinematics import carriage_motion, carriage_tilt
from imu_square.simulate.machine import MachineModel
from imu_square.simulate.sensor import SensorModel
from imu_square.simulate.sensor_noise import digitise, sensor_noise
from imu_square.simulate.trajectory import build_timeline
from imu_square.simulate.truth import build_truth, trajectory_source

DEFAULT_T0_NS = 1_700_000_000_000_000_000


def _events(timeline, clock_factor, t0_ns):
    out = []
    for b in timeline.blocks:
        for kind, t in (("block_start", b.t_start_s), ("block_end", b.t_end_s)):
            out.append(
                Event(
                    time_ns=t0_ns + round(t * clock_factor * 1e9),
                    kind=kind,
                    direction=b.direction,
                    block=b.index,
                )
            )
    return out


def simulate_run(
    program,
    machine=None,
    sensor=None,
    *,
    seed=None,
    lead_in_s=3.0,
    lead_out_s=3.0,
    events=True,
    t0_ns=DEFAULT_T0_NS,
    uptime_s=0.0,
    motion=None,
):
    """Simulate the accelerometer recording of a circle test.

    Parameters
    ----------
    program : TestProgram
        The test program.
    machine : MachineModel, optional
        The machine; ideal by default.
    sensor : SensorModel, optional
        The sensor; ideal and noiseless by default.
    seed : int, optional
        Seed of the noise; drawn at random (and written to the truth) if None.
    lead_in_s, lead_out_s : float
        Idle time recorded before the first and after the last block. [s]
    events : bool
        Whether to add block_start/block_end events at the true motion start
        and end of each block.
    t0_ns : int
        Recording time of the first sample. [ns]
    uptime_s : float
        How long the sensor board has been powered at the first sample: its
        sample counter starts there, and its warm-up (thermal drift,
        temperature) is that far along. [s]
    motion : SampledMotion, optional
        What the axes were commanded to do: a controller's sampled motion of
        ``program`` (:mod:`imu_square.simulate.sampled_motion`), placed here
        with ``lead_in_s`` and ``lead_out_s``. By default our own trajectory
        (:mod:`imu_square.simulate.trajectory`) with the machine's feed ramps.

    Returns
    -------
    recording : Recording
        Samples as float32, sensor-clock timestamps.
    truth : dict
        See :func:`imu_square.simulate.truth.build_truth`.
    """
    machine = MachineModel() if machine is None else machine
    sensor = SensorModel() if sensor is None else sensor
    for name, value in (
        ("lead_in_s", lead_in_s),
        ("lead_out_s", lead_out_s),
        ("uptime_s", uptime_s),
    ):
        if not (math.isfinite(value) and value >= 0):
            raise ConfigError(f"{name} must be a finite number >= 0, got {value!r}")
    if seed is None:
        seed = secrets.randbits(63)
    if motion is None:
        timeline = build_timeline(
            program, machine.ramp_s, machine.ramp_profile, lead_in_s, lead_out_s
        )
        run_program, source = program, trajectory_source(machine)
    elif motion.program != program:
        raise ControllerError(
            "the motion given was sampled from another program than the one given"
        )
    else:
        timeline = motion.placed(lead_in_s, lead_out_s)
        run_program, source = motion.as_run(program), motion.source
    dt_ns = round(1e9 / sensor.sample_rate_hz)
    clock_factor = 1.0 + sensor.clock_ppm * 1e-6
    n = math.floor(timeline.duration_s * clock_factor * 1e9 / dt_ns) + 1
    index = np.arange(n, dtype=np.int64)
    t = index * (dt_ns * 1e-9) / clock_factor

    pos, _, acc = carriage_motion(timeline, machine, t)
    tilt = carriage_tilt(pos, machine)
    yaw = machine.geometry.carriage_yaw(pos[:, 0], pos[:, 1])
    f = sensor.apply_gain(sensor.sense(acc, tilt, yaw, t + uptime_s))
    rng = np.random.default_rng(seed)
    if sensor.noise_density_m_s2_rthz > 0:
        f += sensor_noise(
            n, 1e9 / dt_ns, sensor.noise_density_m_s2_rthz, sensor.flicker_corner_hz, rng
        )
    accel = digitise(f, sensor.resolution_m_s2, sensor.range_m_s2)

    recording = Recording(
        accel=accel,
        time_ns=t0_ns + index * dt_ns,
        seq=index + round(uptime_s * 1e9 / dt_ns),
        dt_ns=dt_ns,
        program=program,
        sensor=SensorInfo(
            model=sensor.model,
            serial=f"sim-{sensor.model}"[:32],
            noise_density_m_s2_rthz=sensor.noise_density_m_s2_rthz,
            range_m_s2=sensor.range_m_s2,
            resolution_m_s2=sensor.resolution_m_s2 if sensor.resolution_m_s2 > 0 else math.nan,
        ),
        machine_id=machine.name,
        events=_events(timeline, clock_factor, t0_ns) if events else [],
        temperature_c=sensor.temperature_at(t + uptime_s),
        metadata={"producer": "imu-square simulate", "seed": str(seed)},
    )
    truth = build_truth(
        program, machine, sensor, timeline, seed, clock_factor, t0_ns, uptime_s, run_program
    )
    truth["motion"] = source
    if motion is not None:
        truth["ramp_s"], truth["ramp_profile"] = timeline.ramp_s, "sampled"
    truth["n_samples"] = n
    truth["t0_ns"] = t0_ns
    return recording, truth
