"""Monte Carlo helpers of the benchmarks: one noiseless run, many noisy replicas.

The simulator adds its noise after the physics (``simulate_run``: sense, gain,
then ``sensor_noise``, then ``digitise``), so a noiseless run plus noise drawn
with the same ``sensor_noise`` and ``digitise`` is a simulated run with
another noise seed, at a fraction of the cost.
"""

import math
import warnings
from dataclasses import replace

import numpy as np

from imu_square.io.recording import SensorInfo
from imu_square.pipeline.gravity import analyze_feeds, separate_gravity
from imu_square.pipeline.squareness import analyze
from imu_square.simulate import simulate_run
from imu_square.simulate.sensor_noise import digitise, sensor_noise


def noiseless_run(program, machine, sensor):
    """The run without noise, ADC steps or clipping, and its truth."""
    quiet = replace(sensor, noise_density_m_s2_rthz=0.0, resolution_m_s2=0.0, range_m_s2=math.inf)
    return simulate_run(program, machine, quiet, seed=0)


def replica(base, sensor, seed):
    """``base`` with the sensor's noise (white and 1/f), ADC steps and clipping added."""
    rng = np.random.default_rng(seed)
    d, fc = sensor.noise_density_m_s2_rthz, sensor.flicker_corner_hz
    f = base.accel.astype(np.float64)
    if d > 0:
        f = f + sensor_noise(base.n_samples, base.sample_rate_hz, d, fc, rng)
    accel = digitise(f, sensor.resolution_m_s2, sensor.range_m_s2)
    info = SensorInfo(
        model=sensor.model,
        noise_density_m_s2_rthz=d,
        range_m_s2=sensor.range_m_s2,
        resolution_m_s2=sensor.resolution_m_s2 if sensor.resolution_m_s2 > 0 else math.nan,
    )
    return replace(base, accel=accel, sensor=info)


def estimate(recording, options):
    """theta_y - theta_x, its type A uncertainty and bound; freed of gravity with several feeds.

    Returns
    -------
    dict
        ``squareness_rad``, ``u_squareness_rad``, ``crb_rad`` and, with several
        feeds, ``gravity_coupling_rad_per_m``; or ``error`` if the analysis refused.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            if recording.program.n_feeds > 1:
                sep = separate_gravity(analyze_feeds([("run", recording)], options))
                return {
                    "squareness_rad": sep.squareness_rad,
                    "u_squareness_rad": sep.u_squareness_rad,
                    "crb_rad": sep.crb_rad,
                    "gravity_coupling_rad_per_m": sep.gravity_coupling_rad_per_m,
                }
            r = analyze(recording, options)
        except Exception as exc:  # counted as a failure in the table
            return {"error": f"{type(exc).__name__}: {exc}"}
    return {
        "squareness_rad": r.squareness_rad,
        "u_squareness_rad": r.u_squareness_rad,
        "crb_rad": r.crb_rad,
    }


def spread(values):
    """Mean, standard deviation and the 95 % interval of the standard deviation (chi-square)."""
    from scipy import stats

    values = np.asarray(values, dtype=float)
    n = values.size
    sd = float(np.std(values, ddof=1))
    lo = sd * math.sqrt((n - 1) / stats.chi2.ppf(0.975, n - 1))
    hi = sd * math.sqrt((n - 1) / stats.chi2.ppf(0.025, n - 1))
    return float(np.mean(values)), sd, (lo, hi)
