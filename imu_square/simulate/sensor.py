"""The accelerometer: mounting, non-orthogonality, gravity, gain, noise; and its TOML file.

A sensor file (all sections optional; absent = ideal, noiseless)::

    [sensor]
    model = "ADXL355"
    sample_rate_hz = 1000.0
    noise_density_ug_rthz = 7.0     # white noise per axis
    flicker_corner_hz = 0.0         # 1/f corner: PSD d^2 (1 + fc/f); 0 = none
    range_g = 2.048                 # full scale (clipping); inf = none
    resolution_ug = 3.9             # ADC step; 0 = none
    eps_c_deg = 2.1                 # rotation of the sensor about Z on the table
    beta_urad = 0.0                 # non-orthogonality (E_SC0X) once warm
    tilt_x_urad = 0.0               # static tilt: g*tilt leaks into x and y
    tilt_y_urad = 0.0
    temperature_c = nan             # ambient temperature; a number adds a temperature channel

    [sensor_thermal_drift]          # beta(t) = beta + (beta_0 - beta) exp(-t/tau)
    beta_0_urad = 200.0             # required when the section is present
    tau_warm_s = 600.0
    temperature_rise_c = 0.0        # the electronics warm by this much with the same tau

    [sensor_gain_mismatch]
    gain_percent = [0.0, 0.0, 0.0]  # x, y, z
    bias_mg = [0.0, 0.0, 0.0]

    [sample_clock_error]
    ppm = 0.0                       # the sensor clock runs fast by this much

Sensor frame (docs/model.md): the sensor frame is the machine frame turned by
``+eps_c`` about Z, ``a_s = R(-eps_c) a``; its y axis leans by ``beta`` towards
-x: ``a_sy = -sin(beta) a_x + cos(beta) a_y``. The sensor reads specific force,
so a level sensor at rest reads ``+g`` on z.
"""

import math
from dataclasses import dataclass

import numpy as np

from imu_square.errors import ConfigError
from imu_square.textfile import read_toml
from imu_square.units import UG, G
from imu_square.validation import read_tables


@dataclass(frozen=True)
class SensorModel:
    """An accelerometer, in SI units. Defaults: an ideal, noiseless sensor.

    Attributes
    ----------
    model : str
        Sensor model name.
    sample_rate_hz : float
        Nominal sample rate on the sensor's clock. [Hz]
    noise_density_m_s2_rthz : float
        White-noise density d per axis. [m/s^2/sqrt(Hz)]
    flicker_corner_hz : float
        Corner of the 1/f noise: PSD ``d^2 (1 + fc/f)``; 0 for none. [Hz]
    range_m_s2 : float
        Full scale; readings are clipped to +-range. [m/s^2]
    resolution_m_s2 : float
        ADC step; 0 for none. [m/s^2]
    eps_c_rad : float
        Mounting rotation about Z. [rad]
    beta_rad : float
        Non-orthogonality once warm. [rad]
    beta_0_rad : float or None
        Non-orthogonality at power-on (thermal drift); None for no drift. [rad]
    tau_warm_s : float
        Warm-up time constant. [s]
    temperature_c : float
        Ambient temperature of the sensor at power-on; NaN for no temperature
        channel. [degC]
    temperature_rise_c : float
        How much the sensor warms from power-on, with the time constant
        ``tau_warm_s``: its temperature is
        ``temperature_c + rise (1 - exp(-t / tau_warm))``, so a thermal drift
        of ``beta`` is exactly linear in the temperature. [degC]
    tilt_rad : tuple of 2 float
        Static mounting tilt of the sensor's x and y axes (they read
        ``g * tilt`` at rest, in the sensor frame). [rad]
    gain : tuple of 3 float
        Gain error per axis (reading ``(1 + gain) * f``).
    bias_m_s2 : tuple of 3 float
        Bias per axis. [m/s^2]
    clock_ppm : float
        Sample clock error: the clock runs fast by this many ppm. [1e-6]
    """

    model: str = "ideal"
    sample_rate_hz: float = 1000.0
    noise_density_m_s2_rthz: float = 0.0
    flicker_corner_hz: float = 0.0
    range_m_s2: float = math.inf
    resolution_m_s2: float = 0.0
    eps_c_rad: float = 0.0
    beta_rad: float = 0.0
    beta_0_rad: float | None = None
    tau_warm_s: float = 600.0
    temperature_c: float = math.nan
    temperature_rise_c: float = 0.0
    tilt_rad: tuple = (0.0, 0.0)
    gain: tuple = (0.0, 0.0, 0.0)
    bias_m_s2: tuple = (0.0, 0.0, 0.0)
    clock_ppm: float = 0.0

    def beta_at(self, t):
        """Non-orthogonality at true time ``t`` from power-on (the first sample). [rad]"""
        t = np.asarray(t, dtype=float)
        if self.beta_0_rad is None:
            return np.full_like(t, self.beta_rad)
        return self.beta_rad + (self.beta_0_rad - self.beta_rad) * np.exp(-t / self.tau_warm_s)

    def temperature_at(self, t):
        """Sensor temperature at true time ``t`` from power-on, to 0.01 degC; None without a
        temperature channel. [degC]"""
        if not math.isfinite(self.temperature_c):
            return None
        t = np.asarray(t, dtype=float)
        warm = self.temperature_rise_c * -np.expm1(-t / self.tau_warm_s)
        return np.round(self.temperature_c + warm, 2)  # the wire protocol's resolution

    def mean_beta(self, t0, t1):
        """Mean non-orthogonality over true times [t0, t1]. [rad]"""
        if self.beta_0_rad is None or t1 <= t0:
            return float(self.beta_at(t0))
        tau = self.tau_warm_s
        integral = tau * (math.exp(-t0 / tau) - math.exp(-t1 / tau))
        return self.beta_rad + (self.beta_0_rad - self.beta_rad) * integral / (t1 - t0)

    def effects(self):
        """The named sensor effects that are on, with their parameters (SI).

        Returns
        -------
        dict of str to dict
        """
        out = {}
        if self.beta_0_rad is not None and self.beta_0_rad != self.beta_rad:
            out["sensor_thermal_drift"] = {
                "beta_0_rad": self.beta_0_rad,
                "beta_rad": self.beta_rad,
                "tau_warm_s": self.tau_warm_s,
                "temperature_rise_c": self.temperature_rise_c,
            }
        if any(self.gain) or any(self.bias_m_s2):
            out["sensor_gain_mismatch"] = {
                "gain": list(self.gain),
                "bias_m_s2": list(self.bias_m_s2),
            }
        if self.clock_ppm:
            out["sample_clock_error"] = {"ppm": self.clock_ppm}
        return out

    def sense(self, acc_xy, tilt_xy, yaw, t):
        """Noise-free specific force in the sensor frame.

        Parameters
        ----------
        acc_xy : ndarray, shape (n, 2)
            Acceleration of the carriage in the machine frame. [m/s^2]
        tilt_xy : tuple of 2 ndarray or float
            Tilt of the carriage (gravity coupling) along the machine's X and Y:
            gravity leaks ``g * tilt`` into the machine-frame X and Y. [rad]
        yaw : ndarray, shape (n,) or float
            Yaw of the carriage, added to ``eps_c``. [rad]
        t : ndarray, shape (n,)
            True time from the first sample (thermal drift). [s]

        Returns
        -------
        ndarray, shape (n, 3)
            Specific force along the sensor's x, y, z, before gain and noise. [m/s^2]
        """
        fx = acc_xy[:, 0] + G * tilt_xy[0]
        fy = acc_xy[:, 1] + G * tilt_xy[1]
        eps = self.eps_c_rad + yaw
        c, s = np.cos(eps), np.sin(eps)
        # machine frame -> orthogonal sensor frame, plus the sensor's own mounting tilt
        rx = c * fx + s * fy + G * self.tilt_rad[0]
        ry = -s * fx + c * fy + G * self.tilt_rad[1]
        # without a warm-up drift, beta is one number: its sine once, not once a sample
        beta = self.beta_rad if self.beta_0_rad is None else self.beta_at(t)
        out = np.empty((len(t), 3))
        out[:, 0] = rx
        out[:, 1] = -np.sin(beta) * rx + np.cos(beta) * ry
        tx = tilt_xy[0] + self.tilt_rad[0]
        ty = tilt_xy[1] + self.tilt_rad[1]
        out[:, 2] = G * np.sqrt(1.0 - tx * tx - ty * ty)
        return out

    def apply_gain(self, f):
        """Per-axis gain and bias, in place on ``f`` of shape (n, 3). [m/s^2]"""
        for k in range(3):
            if self.gain[k] or self.bias_m_s2[k]:
                f[:, k] = (1.0 + self.gain[k]) * f[:, k] + self.bias_m_s2[k]
        return f


_LAYOUT = {
    "sensor": {
        "model": "ideal",
        "sample_rate_hz": 1000.0,
        "noise_density_ug_rthz": 0.0,
        "flicker_corner_hz": 0.0,
        "range_g": math.inf,
        "resolution_ug": 0.0,
        "eps_c_deg": 0.0,
        "beta_urad": 0.0,
        "tilt_x_urad": 0.0,
        "tilt_y_urad": 0.0,
        "temperature_c": math.nan,
    },
    "sensor_thermal_drift": {"beta_0_urad": 0.0, "tau_warm_s": 600.0, "temperature_rise_c": 0.0},
    "sensor_gain_mismatch": {"gain_percent": [0.0, 0.0, 0.0], "bias_mg": [0.0, 0.0, 0.0]},
    "sample_clock_error": {"ppm": 0.0},
}


def sensor_from_mapping(doc, source="<sensor>"):
    """Validate a parsed sensor file and convert it to SI.

    Parameters
    ----------
    doc : dict
        Parsed TOML (see the module docstring for the layout).
    source : str
        Where it came from, for messages.

    Returns
    -------
    SensorModel

    Raises
    ------
    ConfigError
        Naming the file, section and field, what is allowed and what was received.
    """
    t = read_tables(doc, _LAYOUT, source, ConfigError, terse=True)
    sensor, drift, gains = t["sensor"], t["sensor_thermal_drift"], t["sensor_gain_mismatch"]
    beta = sensor.number("beta_urad", -1e5, 1e5) * 1e-6
    drifts = "sensor_thermal_drift" in doc
    if drifts and not drift.has("beta_0_urad"):
        raise ConfigError(
            f"{source}: [sensor_thermal_drift] needs beta_0_urad (the non-orthogonality at "
            f"power-on, urad); got only {sorted(doc['sensor_thermal_drift'])!r}"
        )

    def triple(key, scale, limit):
        what = f"three numbers [x, y, z] within +-{limit:g}"
        return tuple(v * scale for v in gains.numbers(key, (3,), what, -limit, limit))

    return SensorModel(
        model=sensor.text("model"),
        sample_rate_hz=sensor.number("sample_rate_hz", 0.0, 1e6, lo_open=True),
        noise_density_m_s2_rthz=sensor.number("noise_density_ug_rthz", 0.0, 1e6) * UG,
        flicker_corner_hz=sensor.number("flicker_corner_hz", 0.0, 1e4),
        range_m_s2=sensor.number("range_g", 0.0, math.inf, lo_open=True) * G,
        resolution_m_s2=sensor.number("resolution_ug", 0.0, 1e6) * UG,
        eps_c_rad=sensor.number("eps_c_deg", -180.0, 180.0) * (math.pi / 180),
        beta_rad=beta,
        beta_0_rad=drift.number("beta_0_urad", -1e5, 1e5) * 1e-6 if drifts else None,
        tau_warm_s=drift.number("tau_warm_s", 0.0, 1e6, lo_open=True),
        # no temperature channel unless the file gives the ambient temperature
        temperature_c=sensor.number("temperature_c", -60.0, 150.0)
        if sensor.has("temperature_c")
        else math.nan,
        temperature_rise_c=drift.number("temperature_rise_c", -100, 100),
        tilt_rad=(
            sensor.number("tilt_x_urad", -1e5, 1e5) * 1e-6,
            sensor.number("tilt_y_urad", -1e5, 1e5) * 1e-6,
        ),
        gain=triple("gain_percent", 1e-2, 50.0),
        bias_m_s2=triple("bias_mg", 1e-3 * G, 1e4),
        clock_ppm=t["sample_clock_error"].number("ppm", -1e4, 1e4),
    )


def read_sensor(path):
    """Read a sensor description file.

    Parameters
    ----------
    path : str or Path
        TOML file; see the module docstring for the layout.

    Returns
    -------
    SensorModel
    """
    return sensor_from_mapping(read_toml(path, ConfigError), str(path))
