"""The machine description: geometry, drives, feed ramps, tilt; and its TOML file.

A machine file (all sections optional; absent = ideal)::

    [machine]
    name = "typical"
    ramp_s = 0.15                 # feed ramp at each block end
    ramp_profile = "trapezoid"    # or "s_curve" (jerk-limited)

    [geometry]
    machine_squareness_um_per_m = 15.0  # alpha (E_C0X), + when the XY angle exceeds 90 deg
    axis_length_mm = [800.0, 800.0]
    axis_centre_mm = [0.0, 0.0]   # middle of the X and Y travels

    [squareness_drift]
    rate_um_per_m_per_h = 0.0

    [scale_mismatch]
    x_um_per_m = 0.0
    y_um_per_m = 0.0

    [straightness_yaw]            # Chapman Appendix I
    x_um = 0.0                    # bow S of the X axis (in Y) at the travel ends
    y_um = 0.0
    x_quartic_um = 0.0            # quartic part Q (2x/L)^4 of the X form (Chapman's machine 7)
    yaw_x = false                 # with the associated yaw
    yaw_y = false

    [servo_mismatch]
    tau_x_ms = 0.0                # servo time constant of each axis
    tau_y_ms = 0.0
    model = "pure_lag"            # or "first_order": 1/(1 + s tau), shrinks the circle

    [backlash]
    x_um = 0.0                    # negative: over-compensated (the table is thrown ahead)
    y_um = 0.0
    take_up_ms = 5.0
    onset = 0.0                   # centre of the take-up after the reversal, in take-up times

    [reversal_spikes]
    peak_x_m_s2 = 0.0             # peak of the acceleration bump (negative: inward)
    peak_y_m_s2 = 0.0
    tau_ms = 20.0
    onset_tau = 0.0               # its start after the reversal, in tau (-2: centred, < -2: led)
    symmetric = false             # an even bump peaking at (onset_tau + 2) tau: a stick zone

    [structural_vibration]
    accel_x_m_s2 = 0.0
    accel_y_m_s2 = 0.0
    frequency_hz = 40.0
    damping_ratio = 0.05
    start_stop_m_s2 = 0.0         # the same mode rung at the corners of the feed ramps (30 ms on)
    start_stop_quadrature_m_s2 = 0.0  # ... a quarter period later (a ramp of constant jerk)

    [gravity_coupling]            # carriage tilt leaking g*tilt into a channel
    x_per_x_urad_per_m = 0.0      # tilt seen by x per metre of X travel
    x_per_y_urad_per_m = 0.0
    y_per_x_urad_per_m = 0.0
    y_per_y_urad_per_m = 0.0
"""

import math
import warnings
from dataclasses import dataclass, field

from imu_square.errors import ConfigError, ImuSquareWarning
from imu_square.simulate.drive import RAMP_RING_SIZED_AT_S
from imu_square.simulate.geometry import Geometry
from imu_square.simulate.kinematics import SERVO_MODELS
from imu_square.simulate.trajectory import RAMP_PROFILES
from imu_square.textfile import read_toml
from imu_square.units import HOUR, MS, UM
from imu_square.validation import read_tables

# The most a mode rung by the feed ramps may decay, in e-folds, by when it is sized.
_MAX_RING_DECAY = 50.0


@dataclass(frozen=True)
class MachineModel:
    """A machine tool's errors in the XY plane, in SI units. Defaults: an ideal machine.

    Attributes
    ----------
    name : str
        Label written to the recording.
    geometry : Geometry
        Squareness (and its drift), scale, straightness and yaw.
    ramp_s : float
        Duration of each feed ramp. [s]
    ramp_profile : str
        ``"trapezoid"`` or ``"s_curve"``.
    tau_x_s, tau_y_s : float
        Servo time constant of each axis: its lag for a pure lag. [s]
    servo_model : str
        ``"pure_lag"`` or ``"first_order"``
        (:mod:`imu_square.simulate.kinematics`).
    backlash_x_m, backlash_y_m : float
        Lost motion of each axis; negative when the control's compensation
        exceeds it (the table is thrown ahead at a reversal). [m]
    backlash_take_up_s : float
        Time constant of the take-up. [s]
    backlash_onset : float
        Centre of the take-up after the reversal, in units of
        ``backlash_take_up_s`` (0: centred on it; 2 or more: it starts there).
    spike_x_m_s2, spike_y_m_s2 : float
        Peak acceleration of the friction bump at a reversal; positive outward
        (the axis lags its new direction), negative inward (an over-set
        friction compensation). [m/s^2]
    spike_tau_s : float
        Time constant of the bump. [s]
    spike_onset : float
        Start of the bump relative to the reversal, in units of
        ``spike_tau_s``: 0 starts at the reversal (after it), -2 puts its
        position peak on the reversal (centred), below that it leads.
    spike_symmetric : bool
        The bump's form: skewed (false: friction building up after its
        start) or symmetric (true: a stick zone around the reversal, the
        table keeping ``tanh^2`` of the commanded speed), its peak at
        ``(spike_onset + 2) spike_tau_s`` either way
        (:func:`~imu_square.simulate.drive.add_spikes`).
    vibration_x_m_s2, vibration_y_m_s2 : float
        Initial acceleration of the oscillation excited at a reversal. [m/s^2]
    vibration_hz : float
        Natural frequency of the structure. [Hz]
    vibration_damping : float
        Damping ratio.
    vibration_start_stop_m_s2 : float
        Amplitude of the same mode rung at each corner of the feed ramps
        (where the acceleration steps), along the step (along the direction
        of motion at the start and the end of motion), 30 ms after the corner
        (:data:`~imu_square.simulate.drive.RAMP_RING_SIZED_AT_S`); signed. [m/s^2]
    vibration_start_stop_quadrature_m_s2 : float
        Amplitude of its quadrature, the ringing a smooth ramp's jerk step
        starts (zero acceleration at the corner, a sine along the step), as
        long after the corner; signed. [m/s^2]
    tilt_per_m : tuple of 4 float
        Gravity coupling: tilt seen by the x channel per metre of X and of Y
        travel, then by the y channel per metre of X and of Y. [rad/m]
    """

    name: str = "ideal"
    geometry: Geometry = field(default_factory=Geometry)
    ramp_s: float = 0.15
    ramp_profile: str = "trapezoid"
    tau_x_s: float = 0.0
    tau_y_s: float = 0.0
    servo_model: str = "pure_lag"
    backlash_x_m: float = 0.0
    backlash_y_m: float = 0.0
    backlash_take_up_s: float = 0.005
    backlash_onset: float = 0.0
    spike_x_m_s2: float = 0.0
    spike_y_m_s2: float = 0.0
    spike_tau_s: float = 0.02
    spike_onset: float = 0.0
    spike_symmetric: bool = False
    vibration_x_m_s2: float = 0.0
    vibration_y_m_s2: float = 0.0
    vibration_hz: float = 40.0
    vibration_damping: float = 0.05
    vibration_start_stop_m_s2: float = 0.0
    vibration_start_stop_quadrature_m_s2: float = 0.0
    tilt_per_m: tuple = (0.0, 0.0, 0.0, 0.0)

    def effects(self):
        """The named effects that are on, with their parameters (SI), for the truth file.

        Returns
        -------
        dict of str to dict
        """
        g = self.geometry
        out = {}
        if g.machine_squareness_rate_rad_s:
            out["squareness_drift"] = {"rate_rad_s": g.machine_squareness_rate_rad_s}
        if g.scale_x or g.scale_y:
            out["scale_mismatch"] = {"scale_x": g.scale_x, "scale_y": g.scale_y}
        if g.straightness_x_m or g.straightness_y_m or g.straightness_x_quartic_m:
            out["straightness_yaw"] = {
                "straightness_x_m": g.straightness_x_m,
                "straightness_y_m": g.straightness_y_m,
                "straightness_x_quartic_m": g.straightness_x_quartic_m,
                "length_x_m": g.length_x_m,
                "length_y_m": g.length_y_m,
                "axis_centre_m": list(g.axis_centre_m),
                "yaw_x": g.yaw_x,
                "yaw_y": g.yaw_y,
            }
        if self.tau_x_s or self.tau_y_s:
            out["servo_mismatch"] = {
                "tau_x_s": self.tau_x_s,
                "tau_y_s": self.tau_y_s,
                "model": self.servo_model,
            }
        if self.backlash_x_m or self.backlash_y_m:
            out["backlash"] = {
                "backlash_x_m": self.backlash_x_m,
                "backlash_y_m": self.backlash_y_m,
                "take_up_s": self.backlash_take_up_s,
                "onset": self.backlash_onset,
            }
        if self.spike_x_m_s2 or self.spike_y_m_s2:
            out["reversal_spikes"] = {
                "peak_x_m_s2": self.spike_x_m_s2,
                "peak_y_m_s2": self.spike_y_m_s2,
                "tau_s": self.spike_tau_s,
                "onset_tau": self.spike_onset,
            }
            if self.spike_symmetric:  # only then: the skewed form's truth is as it was
                out["reversal_spikes"]["symmetric"] = True
        quadrature = self.vibration_start_stop_quadrature_m_s2
        if (
            self.vibration_x_m_s2
            or self.vibration_y_m_s2
            or self.vibration_start_stop_m_s2
            or quadrature
        ):
            out["structural_vibration"] = {
                "accel_x_m_s2": self.vibration_x_m_s2,
                "accel_y_m_s2": self.vibration_y_m_s2,
                "frequency_hz": self.vibration_hz,
                "damping_ratio": self.vibration_damping,
            }
            if self.vibration_start_stop_m_s2:
                out["structural_vibration"]["start_stop_m_s2"] = self.vibration_start_stop_m_s2
            if quadrature:
                out["structural_vibration"]["start_stop_quadrature_m_s2"] = quadrature
        if any(self.tilt_per_m):
            out["gravity_coupling"] = dict(
                zip(
                    ("x_per_x_rad_m", "x_per_y_rad_m", "y_per_x_rad_m", "y_per_y_rad_m"),
                    self.tilt_per_m,
                    strict=True,
                )
            )
        return out


# The name of machine_squareness_um_per_m until 0.1; read, with a warning, for one release.
_LEGACY_SQUARENESS_KEY = "squareness_um_per_m"

_LAYOUT = {
    "machine": {"name": "machine", "ramp_s": 0.15, "ramp_profile": "trapezoid"},
    "geometry": {
        "machine_squareness_um_per_m": 0.0,
        _LEGACY_SQUARENESS_KEY: 0.0,
        "axis_length_mm": [800.0, 800.0],
        "axis_centre_mm": [0.0, 0.0],
    },
    "squareness_drift": {"rate_um_per_m_per_h": 0.0},
    "scale_mismatch": {"x_um_per_m": 0.0, "y_um_per_m": 0.0},
    "straightness_yaw": {
        "x_um": 0.0,
        "y_um": 0.0,
        "x_quartic_um": 0.0,
        "yaw_x": False,
        "yaw_y": False,
    },
    "servo_mismatch": {"tau_x_ms": 0.0, "tau_y_ms": 0.0, "model": "pure_lag"},
    "backlash": {"x_um": 0.0, "y_um": 0.0, "take_up_ms": 5.0, "onset": 0.0},
    "reversal_spikes": {
        "peak_x_m_s2": 0.0,
        "peak_y_m_s2": 0.0,
        "tau_ms": 20.0,
        "onset_tau": 0.0,
        "symmetric": False,
    },
    "structural_vibration": {
        "accel_x_m_s2": 0.0,
        "accel_y_m_s2": 0.0,
        "frequency_hz": 40.0,
        "damping_ratio": 0.05,
        "start_stop_m_s2": 0.0,
        "start_stop_quadrature_m_s2": 0.0,
    },
    "gravity_coupling": {
        "x_per_x_urad_per_m": 0.0,
        "x_per_y_urad_per_m": 0.0,
        "y_per_x_urad_per_m": 0.0,
        "y_per_y_urad_per_m": 0.0,
    },
}


def _squareness_key(geometry, source):
    """The [geometry] field that holds alpha: the new name, or the old one with a warning."""
    if not geometry.has(_LEGACY_SQUARENESS_KEY):
        return "machine_squareness_um_per_m"
    if geometry.has("machine_squareness_um_per_m"):
        raise ConfigError(
            f"{source}: [geometry] has both machine_squareness_um_per_m and its old name "
            f"{_LEGACY_SQUARENESS_KEY}: keep machine_squareness_um_per_m only"
        )
    warnings.warn(
        f"{source}: [geometry] {_LEGACY_SQUARENESS_KEY} is now machine_squareness_um_per_m; "
        f"the old name is read until the next release",
        ImuSquareWarning,
        stacklevel=3,
    )
    return _LEGACY_SQUARENESS_KEY


def machine_from_mapping(doc, source="<machine>"):
    """Validate a parsed machine file and convert it to SI.

    Parameters
    ----------
    doc : dict
        Parsed TOML (see the module docstring for the layout).
    source : str
        Where it came from, for messages.

    Returns
    -------
    MachineModel

    Raises
    ------
    ConfigError
        Naming the file, section and field, what is allowed and what was received.
    """
    t = read_tables(doc, _LAYOUT, source, ConfigError, terse=True)
    machine, geo, yaw = t["machine"], t["geometry"], t["straightness_yaw"]
    servo, backlash, spikes = t["servo_mismatch"], t["backlash"], t["reversal_spikes"]
    vibration = t["structural_vibration"]
    pair = "two finite numbers [a, b]"
    lengths = geo.numbers("axis_length_mm", (2,), pair)
    if min(lengths) <= 0:
        geo.fail("axis_length_mm", "positive", geo.get("axis_length_mm"))
    geometry = Geometry(
        machine_squareness_rad=geo.number(_squareness_key(geo, source), -1e4, 1e4) * UM,
        machine_squareness_rate_rad_s=t["squareness_drift"].number("rate_um_per_m_per_h", -1e4, 1e4)
        * (UM / HOUR),
        scale_x=t["scale_mismatch"].number("x_um_per_m", -1e4, 1e4) * UM,
        scale_y=t["scale_mismatch"].number("y_um_per_m", -1e4, 1e4) * UM,
        straightness_x_m=yaw.number("x_um", -1e3, 1e3) * UM,
        straightness_y_m=yaw.number("y_um", -1e3, 1e3) * UM,
        straightness_x_quartic_m=yaw.number("x_quartic_um", -1e3, 1e3) * UM,
        length_x_m=lengths[0] * 1e-3,
        length_y_m=lengths[1] * 1e-3,
        axis_centre_m=tuple(c * 1e-3 for c in geo.numbers("axis_centre_mm", (2,), pair)),
        yaw_x=yaw.flag("yaw_x"),
        yaw_y=yaw.flag("yaw_y"),
    )
    big = 1e6  # urad/m: a tilt rate above 1 rad/m is a unit mistake
    tilt = tuple(
        t["gravity_coupling"].number(key, -big, big) * UM for key in _LAYOUT["gravity_coupling"]
    )
    model = MachineModel(
        name=machine.text("name"),
        geometry=geometry,
        ramp_s=machine.number("ramp_s", 0.0, 5.0, lo_open=True),
        ramp_profile=machine.choice("ramp_profile", RAMP_PROFILES),
        tau_x_s=servo.number("tau_x_ms", 0.0, 1e3) * MS,
        tau_y_s=servo.number("tau_y_ms", 0.0, 1e3) * MS,
        servo_model=servo.choice("model", SERVO_MODELS),
        backlash_x_m=backlash.number("x_um", -1e3, 1e3) * UM,
        backlash_y_m=backlash.number("y_um", -1e3, 1e3) * UM,
        backlash_take_up_s=backlash.number("take_up_ms", 0.0, 1e3, lo_open=True) * MS,
        backlash_onset=backlash.number("onset", -10.0, 10.0),
        spike_x_m_s2=spikes.number("peak_x_m_s2", -100.0, 100.0),
        spike_y_m_s2=spikes.number("peak_y_m_s2", -100.0, 100.0),
        spike_tau_s=spikes.number("tau_ms", 0.0, 1e3, lo_open=True) * MS,
        spike_onset=spikes.number("onset_tau", -10.0, 10.0),
        spike_symmetric=spikes.flag("symmetric"),
        vibration_x_m_s2=vibration.number("accel_x_m_s2", -100.0, 100.0),
        vibration_y_m_s2=vibration.number("accel_y_m_s2", -100.0, 100.0),
        vibration_hz=vibration.number("frequency_hz", 0.0, 1e4, lo_open=True),
        vibration_damping=vibration.number("damping_ratio", 0.0, 1.0, lo_open=True, hi_open=True),
        vibration_start_stop_m_s2=vibration.number("start_stop_m_s2", -100.0, 100.0),
        vibration_start_stop_quadrature_m_s2=vibration.number(
            "start_stop_quadrature_m_s2", -100.0, 100.0
        ),
        tilt_per_m=tilt,
    )
    rung = model.vibration_start_stop_m_s2 or model.vibration_start_stop_quadrature_m_s2
    e_folds_per_damping = 2.0 * math.pi * model.vibration_hz * RAMP_RING_SIZED_AT_S
    if rung and model.vibration_damping * e_folds_per_damping > _MAX_RING_DECAY:
        # sized 30 ms after the corner, it would start e^50 or more larger
        vibration.fail(
            "damping_ratio",
            f"below {_MAX_RING_DECAY / e_folds_per_damping:.3g} with the feed ramps' ringing on"
            " (its size is taken 30 ms after the corner)",
            model.vibration_damping,
        )
    return model


def read_machine(path):
    """Read a machine description file.

    Parameters
    ----------
    path : str or Path
        TOML file; see the module docstring for the layout.

    Returns
    -------
    MachineModel
    """
    return machine_from_mapping(read_toml(path, ConfigError), str(path))
