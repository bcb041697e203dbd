"""What each named effect of the simulator is made of: its parameters, units and ranges.

Every effect of :data:`imu_square.simulate.presets.EFFECTS` declares here the
parameters that switch it on and shape it, each with

- the name of its field in the machine or sensor file (``[servo_mismatch]
  tau_x_ms``), which is also its display unit;
- the factor from that unit to SI;
- its physical range (what a machine tool or a MEMS sensor can plausibly
  have, narrower than what the file accepts);
- its typical value, the preset's (``presets.py``);
- its role: a *size* is zero when the effect is off and the signal grows with
  it; a *shape* (a time constant, a frequency, a flag) says what the effect
  looks like and matters only when a size is not zero. A shape lists the
  values worth trying first (``scan``);
- ``observed_by``: an extra channel that observes the parameter directly
  (the temperature channel shows the sensor's warm-up time constant).

:func:`with_effect_values` sets an effect's parameters on a machine and
sensor. Code that fits or searches the vocabulary (``imu_square.discrepancy``)
reads only this table, so a new effect joins it by declaring its parameters
here.
"""

import math
from dataclasses import dataclass, replace

from imu_square.errors import ConfigError
from imu_square.simulate.presets import EFFECTS
from imu_square.units import HOUR, MS, UM, URAD, G

SIZE = "size"
SHAPE = "shape"


@dataclass(frozen=True)
class EffectParameter:
    """One parameter of a named effect.

    Attributes
    ----------
    effect : str
        The effect's name, one of :data:`EFFECTS`.
    name : str
        Field name in the machine or sensor file's section of the effect; it
        ends with the display unit (``tau_x_ms``).
    unit : str
        Display unit, e.g. ``"ms"``, ``"µm/m"``; ``""`` for a plain number.
    scale : float
        SI value of one display unit.
    low, high : float
        Physical range in display units.
    typical : float
        The preset's value, in display units.
    role : str
        ``"size"`` or ``"shape"``.
    target : str
        ``"machine"`` or ``"sensor"``.
    path : str
        Attribute of the model that holds it: ``"tau_x_s"``,
        ``"geometry.scale_x"``, ``"gain[0]"``; ``"beta_0_rad-beta_rad"`` for
        a value held relative to another attribute.
    scan : tuple of float
        For a shape: values to try first, in display units.
    observed_by : tuple of str
        Extra channels that observe this parameter directly.
    scan_along : str
        For a shape scanned together with another (not across it): that
        one's name; its ``scan`` pairs value by value with the other's, one
        grid axis for both.
    """

    effect: str
    name: str
    unit: str
    scale: float
    low: float
    high: float
    typical: float
    role: str
    target: str
    path: str
    scan: tuple = ()
    observed_by: tuple = ()
    scan_along: str = ""

    @property
    def key(self):
        """``effect.name``, unique over the vocabulary."""
        return f"{self.effect}.{self.name}"

    @property
    def is_flag(self):
        """Whether the parameter is a true/false switch (its scan is of 0 and 1)."""
        return set(self.scan) == {0.0, 1.0} and self.unit == "flag"

    def get(self, machine, sensor):
        """The parameter's SI value on a machine and sensor."""
        obj = machine if self.target == "machine" else sensor
        if "-" in self.path:
            a, b = self.path.split("-")
            first = _get(obj, a)
            return 0.0 if first is None else float(first) - float(_get(obj, b))
        value = _get(obj, self.path)
        choices = _FLAGS.get(self.path.rpartition(".")[2])
        return float(choices.index(value)) if choices else float(value)

    def set(self, machine, sensor, value_si):
        """A new (machine, sensor) with this parameter at ``value_si``."""
        if self.target == "machine":
            return _set(machine, self.path, value_si), sensor
        if "-" in self.path:
            a, b = self.path.split("-")
            return machine, _set(sensor, a, float(_get(sensor, b)) + value_si)
        return machine, _set(sensor, self.path, value_si)


def _split(path):
    head, _, rest = path.partition(".")
    if "[" in head:
        name, index = head[:-1].split("[")
        return name, int(index), rest
    return head, None, rest


def _get(obj, path):
    name, index, rest = _split(path)
    value = getattr(obj, name)
    if index is not None:
        value = value[index]
    return _get(value, rest) if rest else value


# Fields that hold a choice of two: a flag's 0 and 1 in the file's terms.
_FLAGS = {
    "yaw_x": (False, True),
    "yaw_y": (False, True),
    "servo_model": ("pure_lag", "first_order"),
    "spike_symmetric": (False, True),
}


def _set(obj, path, value):
    name, index, rest = _split(path)
    if rest:
        return replace(obj, **{name: _set(getattr(obj, name), rest, value)})
    if name in _FLAGS:
        value = _FLAGS[name][int(value >= 0.5)]
    if index is not None:
        items = list(getattr(obj, name))
        items[index] = value
        value = tuple(items)
    return replace(obj, **{name: value})


def _p(effect, name, unit, scale, low, high, typical, role, target, path, **kw):
    return EffectParameter(effect, name, unit, scale, low, high, typical, role, target, path, **kw)


_UM_PER_M = "µm/m"
_URAD_PER_M = "µrad/m"
_LOG_HZ = tuple(round(10.0 * 1.12**i, 1) for i in range(33))  # 10 Hz to 375 Hz, 12 % apart

EFFECT_PARAMETERS = {
    "servo_mismatch": (
        _p("servo_mismatch", "tau_x_ms", "ms", MS, 0.0, 20.0, 2.0, SIZE, "machine", "tau_x_s"),
        _p("servo_mismatch", "tau_y_ms", "ms", MS, 0.0, 20.0, 3.0, SIZE, "machine", "tau_y_s"),
        # a pure lag, or a first-order loop 1 / (1 + s tau), whose circle is also smaller
        _p(
            "servo_mismatch",
            "first_order",
            "flag",
            1.0,
            0.0,
            1.0,
            0.0,
            SHAPE,
            "machine",
            "servo_model",
            scan=(0.0, 1.0),
        ),
    ),
    "reversal_spikes": (
        _p(
            "reversal_spikes",
            "peak_x_m_s2",
            "m/s²",
            1.0,
            -1.0,
            1.0,
            0.02,
            SIZE,
            "machine",
            "spike_x_m_s2",
        ),
        _p(
            "reversal_spikes",
            "peak_y_m_s2",
            "m/s²",
            1.0,
            -1.0,
            1.0,
            0.02,
            SIZE,
            "machine",
            "spike_y_m_s2",
        ),
        _p(
            "reversal_spikes",
            "onset_tau",
            "",
            1.0,
            -6.0,
            3.0,
            0.0,
            SHAPE,
            "machine",
            "spike_onset",
            # after the reversal, centred on it (in either form), leading it; declared
            # before the width, so that a coarse scan of the product grid steps through widths
            scan=(0.0, -2.0, -2.0, -4.0),
        ),
        # the bump's form, scanned along its timing: friction building up (skewed) after
        # the reversal, centred on it or leading it; a stick zone (symmetric) centred on it
        _p(
            "reversal_spikes",
            "symmetric",
            "flag",
            1.0,
            0.0,
            1.0,
            0.0,
            SHAPE,
            "machine",
            "spike_symmetric",
            scan=(0.0, 0.0, 1.0, 0.0),
            scan_along="onset_tau",
        ),
        _p(
            "reversal_spikes",
            "tau_ms",
            "ms",
            MS,
            3.0,
            150.0,
            20.0,
            SHAPE,
            "machine",
            "spike_tau_s",
            scan=(5.0, 7.0, 10.0, 14.0, 20.0, 28.0, 40.0, 56.0, 80.0),
        ),
    ),
    "backlash": (
        _p("backlash", "x_um", "µm", UM, -100.0, 100.0, 5.0, SIZE, "machine", "backlash_x_m"),
        _p("backlash", "y_um", "µm", UM, -100.0, 100.0, 5.0, SIZE, "machine", "backlash_y_m"),
        # the take-up's timing is scanned as finely as the spike's: a take-up of a few
        # samples placed a sample off is a spike's shape (issue 22: named reversal_spikes)
        _p(
            "backlash",
            "onset",
            "",
            1.0,
            -3.0,
            6.0,
            0.0,
            SHAPE,
            "machine",
            "backlash_onset",
            # centred on the reversal, half after it, starting at it; declared before
            # the take-up, so that a coarse scan of the product grid steps through take-ups
            scan=(0.0, 1.0, 2.0),
        ),
        _p(
            "backlash",
            "take_up_ms",
            "ms",
            MS,
            1.0,
            50.0,
            5.0,
            SHAPE,
            "machine",
            "backlash_take_up_s",
            scan=(1.0, 1.4, 2.0, 2.8, 4.0, 5.6, 8.0, 11.0, 16.0),
        ),
    ),
    "scale_mismatch": (
        _p(
            "scale_mismatch",
            "x_um_per_m",
            _UM_PER_M,
            UM,
            -1000.0,
            1000.0,
            20.0,
            SIZE,
            "machine",
            "geometry.scale_x",
        ),
        _p(
            "scale_mismatch",
            "y_um_per_m",
            _UM_PER_M,
            UM,
            -1000.0,
            1000.0,
            -10.0,
            SIZE,
            "machine",
            "geometry.scale_y",
        ),
    ),
    "straightness_yaw": (
        _p(
            "straightness_yaw",
            "x_um",
            "µm",
            UM,
            -100.0,
            100.0,
            10.0,
            SIZE,
            "machine",
            "geometry.straightness_x_m",
        ),
        _p(
            "straightness_yaw",
            "y_um",
            "µm",
            UM,
            -100.0,
            100.0,
            10.0,
            SIZE,
            "machine",
            "geometry.straightness_y_m",
        ),
        # Chapman's machine 7: a quartic part Q (2 x / L)^4 of the X axis's form
        _p(
            "straightness_yaw",
            "x_quartic_um",
            "µm",
            UM,
            -1000.0,
            1000.0,
            0.0,
            SIZE,
            "machine",
            "geometry.straightness_x_quartic_m",
        ),
        _p(
            "straightness_yaw",
            "yaw_x",
            "flag",
            1.0,
            0.0,
            1.0,
            1.0,
            SHAPE,
            "machine",
            "geometry.yaw_x",
            scan=(0.0, 1.0),
        ),
        _p(
            "straightness_yaw",
            "yaw_y",
            "flag",
            1.0,
            0.0,
            1.0,
            1.0,
            SHAPE,
            "machine",
            "geometry.yaw_y",
            scan=(0.0, 1.0),
        ),
    ),
    "gravity_coupling": tuple(
        _p(
            "gravity_coupling",
            f"{a}_per_{b}_urad_per_m",
            _URAD_PER_M,
            URAD,
            -1000.0,
            1000.0,
            100.0 if (a, b) == ("x", "y") else 0.0,
            SIZE,
            "machine",
            f"tilt_per_m[{i}]",
        )
        for i, (a, b) in enumerate((("x", "x"), ("x", "y"), ("y", "x"), ("y", "y")))
    ),
    "structural_vibration": (
        _p(
            "structural_vibration",
            "accel_x_m_s2",
            "m/s²",
            1.0,
            -1.0,
            1.0,
            0.01,
            SIZE,
            "machine",
            "vibration_x_m_s2",
        ),
        _p(
            "structural_vibration",
            "accel_y_m_s2",
            "m/s²",
            1.0,
            -1.0,
            1.0,
            0.01,
            SIZE,
            "machine",
            "vibration_y_m_s2",
        ),
        # the same mode rung at each block's start and end of motion, along the motion,
        # sized 30 ms after the ramp's corner (drive.RAMP_RING_SIZED_AT_S)
        _p(
            "structural_vibration",
            "start_stop_m_s2",
            "m/s²",
            1.0,
            -1.0,
            1.0,
            0.0,
            SIZE,
            "machine",
            "vibration_start_stop_m_s2",
        ),
        # ... and its quadrature: the ringing's phase after a ramp depends on the ramp's
        # shape and length, which differ from controller to controller
        _p(
            "structural_vibration",
            "start_stop_quadrature_m_s2",
            "m/s²",
            1.0,
            -1.0,
            1.0,
            0.0,
            SIZE,
            "machine",
            "vibration_start_stop_quadrature_m_s2",
        ),
        _p(
            "structural_vibration",
            "frequency_hz",
            "Hz",
            1.0,
            5.0,
            500.0,
            40.0,
            SHAPE,
            "machine",
            "vibration_hz",
            scan=_LOG_HZ,
        ),
        _p(
            "structural_vibration",
            "damping_ratio",
            "",
            1.0,
            0.005,
            0.5,
            0.05,
            SHAPE,
            "machine",
            "vibration_damping",
            scan=(0.05,),
        ),
    ),
    "sensor_thermal_drift": (
        _p(
            "sensor_thermal_drift",
            "beta_0_urad",
            "µrad",
            URAD,
            -5000.0,
            5000.0,
            200.0,
            SIZE,
            "sensor",
            "beta_0_rad-beta_rad",
        ),
        _p(
            "sensor_thermal_drift",
            "tau_warm_s",
            "s",
            1.0,
            30.0,
            10000.0,
            300.0,
            SHAPE,
            "sensor",
            "tau_warm_s",
            scan=(100.0, 300.0, 1000.0, 3000.0),
            observed_by=("temperature channel",),
        ),
    ),
    "sensor_gain_mismatch": tuple(
        _p(
            "sensor_gain_mismatch",
            f"gain_{a}_percent",
            "%",
            1e-2,
            -5.0,
            5.0,
            g,
            SIZE,
            "sensor",
            f"gain[{i}]",
        )
        for i, (a, g) in enumerate((("x", -0.2), ("y", 0.5), ("z", 0.1)))
    )
    + tuple(
        _p(
            "sensor_gain_mismatch",
            f"bias_{a}_mg",
            "mg",
            1e-3 * G,
            -500.0,
            500.0,
            b,
            SIZE,
            "sensor",
            f"bias_m_s2[{i}]",
        )
        for i, (a, b) in enumerate((("x", 10.0), ("y", -5.0), ("z", 20.0)))
    ),
    "sample_clock_error": (
        _p(
            "sample_clock_error",
            "ppm",
            "ppm",
            1.0,
            -1000.0,
            1000.0,
            50.0,
            SIZE,
            "sensor",
            "clock_ppm",
        ),
    ),
    "squareness_drift": (
        _p(
            "squareness_drift",
            "rate_um_per_m_per_h",
            "µm/m/h",
            UM / HOUR,
            -1000.0,
            1000.0,
            36.0,
            SIZE,
            "machine",
            "geometry.machine_squareness_rate_rad_s",
        ),
    ),
}


def effect_parameters(name):
    """The declared parameters of one effect.

    Parameters
    ----------
    name : str
        One of :data:`EFFECTS`.

    Returns
    -------
    tuple of EffectParameter

    Raises
    ------
    ConfigError
        For a name outside the vocabulary.
    """
    if name not in EFFECT_PARAMETERS:
        raise ConfigError(f"effect {name!r} is not in the vocabulary {list(EFFECTS)}")
    return EFFECT_PARAMETERS[name]


def with_effect_values(name, machine, sensor, values):
    """A machine and sensor with some of an effect's parameters set.

    Parameters
    ----------
    name : str
        One of :data:`EFFECTS`.
    machine : MachineModel
    sensor : SensorModel
    values : dict of str to float
        Parameter name to value in display units; parameters not named keep
        their value.

    Returns
    -------
    machine : MachineModel
    sensor : SensorModel

    Raises
    ------
    ConfigError
        For a parameter the effect does not have, or a value that is not finite.
    """
    params = {p.name: p for p in effect_parameters(name)}
    for key, value in values.items():
        if key not in params:
            raise ConfigError(f"{name}: unknown parameter {key!r}; allowed: {sorted(params)}")
        if not math.isfinite(value):
            raise ConfigError(f"{name}: {key} must be finite, got {value!r}")
        p = params[key]
        machine, sensor = p.set(machine, sensor, value * p.scale)
    return machine, sensor
