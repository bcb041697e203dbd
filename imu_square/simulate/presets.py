"""Named effects at documented default magnitudes.

Each name of the simulator's vocabulary switches on one effect at a magnitude
that is typical and clearly visible in the paper's test (r = 100 mm,
v = 6000 mm/min, so omega = 1 rad/s and v^2/r = 0.1 m/s^2):

=====================  =========================================================
servo_mismatch         tau_x = 2 ms, tau_y = 3 ms: m = omega (tau_y - tau_x)
                       = 1000 urad at the paper's test
reversal_spikes        peak 0.02 m/s^2 (20 % of v^2/r) on both axes, tau 20 ms
backlash               5 um on both axes, taken up over 5 ms
scale_mismatch         x +20 um/m, y -10 um/m
straightness_yaw       Chapman machine 5: S = 10 um on X and Y with yaw, 800 mm
gravity_coupling       the x channel tilts 10 urad per 100 mm of Y travel
                       (about 1e-3 rad of apparent phase at the paper's test)
structural_vibration   0.01 m/s^2 at 40 Hz, damping ratio 0.05, per reversal
sensor_thermal_drift   beta starts 200 urad above its warm value, tau 300 s
sensor_gain_mismatch   gains x -0.2 %, y +0.5 %, z +0.1 %; biases 10, -5, 20 mg
sample_clock_error     the sensor clock runs 50 ppm fast
squareness_drift       +36 urad per hour (1e-8 rad/s)
=====================  =========================================================
"""

from dataclasses import replace

from imu_square.errors import ConfigError
from imu_square.simulate.machine import MachineModel
from imu_square.simulate.sensor import SensorModel
from imu_square.units import G

EFFECTS = (
    "servo_mismatch",
    "reversal_spikes",
    "backlash",
    "scale_mismatch",
    "straightness_yaw",
    "gravity_coupling",
    "structural_vibration",
    "sensor_thermal_drift",
    "sensor_gain_mismatch",
    "sample_clock_error",
    "squareness_drift",
)


def _machine_changes(name, m):
    g = m.geometry
    if name == "servo_mismatch":
        return {"tau_x_s": 2e-3, "tau_y_s": 3e-3}
    if name == "reversal_spikes":
        return {"spike_x_m_s2": 0.02, "spike_y_m_s2": 0.02, "spike_tau_s": 0.02}
    if name == "backlash":
        return {"backlash_x_m": 5e-6, "backlash_y_m": 5e-6, "backlash_take_up_s": 5e-3}
    if name == "scale_mismatch":
        return {"geometry": replace(g, scale_x=20e-6, scale_y=-10e-6)}
    if name == "straightness_yaw":
        return {
            "geometry": replace(
                g,
                straightness_x_m=10e-6,
                straightness_y_m=10e-6,
                length_x_m=0.8,
                length_y_m=0.8,
                yaw_x=True,
                yaw_y=True,
            )
        }
    if name == "gravity_coupling":
        return {"tilt_per_m": (0.0, 1e-4, 0.0, 0.0)}
    if name == "structural_vibration":
        return {
            "vibration_x_m_s2": 0.01,
            "vibration_y_m_s2": 0.01,
            "vibration_hz": 40.0,
            "vibration_damping": 0.05,
        }
    if name == "squareness_drift":
        return {"geometry": replace(g, machine_squareness_rate_rad_s=1e-8)}
    return None


def _sensor_changes(name, s):
    if name == "sensor_thermal_drift":
        return {"beta_0_rad": s.beta_rad + 200e-6, "tau_warm_s": 300.0}
    if name == "sensor_gain_mismatch":
        return {"gain": (-0.002, 0.005, 0.001), "bias_m_s2": (0.01 * G, -0.005 * G, 0.02 * G)}
    if name == "sample_clock_error":
        return {"clock_ppm": 50.0}
    return None


def parse_effects(names):
    """Check effect names.

    Parameters
    ----------
    names : str or iterable of str
        Effect names, or one comma-separated string.

    Returns
    -------
    list of str

    Raises
    ------
    ConfigError
        Naming the first unknown effect and the vocabulary.
    """
    if isinstance(names, str):
        names = [n.strip() for n in names.split(",") if n.strip()]
    names = list(names)
    for name in names:
        if name not in EFFECTS:
            raise ConfigError(f"effects: unknown effect {name!r}; allowed: {list(EFFECTS)}")
    return names


def with_effects(names, machine=None, sensor=None):
    """Switch on named effects at their default magnitudes (see the module table).

    Parameters
    ----------
    names : str or iterable of str
        Effect names from :data:`EFFECTS`, or one comma-separated string.
    machine : MachineModel, optional
        Starting machine; an ideal one by default.
    sensor : SensorModel, optional
        Starting sensor; an ideal one by default.

    Returns
    -------
    machine : MachineModel
    sensor : SensorModel

    Raises
    ------
    ConfigError
        For an unknown effect name.
    """
    machine = MachineModel() if machine is None else machine
    sensor = SensorModel() if sensor is None else sensor
    for name in parse_effects(names):
        changes = _machine_changes(name, machine)
        if changes is not None:
            machine = replace(machine, **changes)
        else:
            sensor = replace(sensor, **_sensor_changes(name, sensor))
    return machine, sensor
