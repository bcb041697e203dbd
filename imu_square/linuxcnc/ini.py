"""A LinuxCNC INI file, and the machine's limits it sets for a circle in the XY plane.

LinuxCNC plans an arc with the smaller of the two in-plane axes' limits: its
speed is at most the smaller ``MAX_VELOCITY``, and its normal (centripetal)
acceleration at most ``sqrt(3)/2`` of the smaller ``MAX_ACCELERATION``, the
rest being kept for the tangential acceleration of the feed ramps [1]_. A feed
above ``sqrt(sqrt(3)/2 a r)`` runs at that speed instead: a machining centre
with 10 m/s^2 axes runs a 25 mm circle at 27,918 mm/min, not 30,000.
``[TRAJ] MAX_LINEAR_VELOCITY`` caps every coordinated move.

References
----------
.. [1] LinuxCNC 2.9, ``src/emc/task/emccanon.cc`` (ARC_FEED: ``a_max_normal =
   a_max_axes * sqrt(3.0)/2.0``) and ``src/emc/tp/blendmath.c``
   (``BLEND_ACC_RATIO_NORMAL``).
"""

import math
from dataclasses import dataclass
from pathlib import Path

from imu_square.errors import ConfigError

# Share of the axis acceleration LinuxCNC allows as an arc's normal acceleration.
ARC_NORMAL_SHARE = math.sqrt(3.0) / 2.0
# Metres per machine unit, by LINEAR_UNITS.
_LINEAR_UNITS = {"mm": 1e-3, "metric": 1e-3, "inch": 0.0254, "in": 0.0254, "imperial": 0.0254}


def read_ini(path):
    """The sections of a LinuxCNC INI file.

    Parameters
    ----------
    path : str or Path
        The INI file.

    Returns
    -------
    dict of str to dict of str to list of str
        Section, key, and every value the key is given (HALFILE repeats).

    Raises
    ------
    ConfigError
        If the file cannot be read, or a line is neither a section, a
        ``KEY = VALUE`` nor a comment.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the LinuxCNC INI file: {exc.strerror}") from None
    sections, current = {}, None
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line[0] in "#;":
            continue
        if line.startswith("[") and line.endswith("]"):
            current = sections.setdefault(line[1:-1].strip(), {})
        elif "=" in line and current is not None:
            key, value = (part.strip() for part in line.split("=", 1))
            current.setdefault(key, []).append(value)
        else:
            raise ConfigError(
                f"{path}:{number}: expected [SECTION], KEY = VALUE or a comment, got {raw!r}"
            )
    return sections


def _value(sections, path, section, key):
    values = sections.get(section, {}).get(key)
    if not values:
        raise ConfigError(f"{path}: [{section}] {key} is missing")
    return values[-1]


def _positive(sections, path, section, key):
    text = _value(sections, path, section, key)
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise ConfigError(f"{path}: [{section}] {key} must be a number > 0, got {text!r}")
    return value


@dataclass(frozen=True)
class ControllerLimits:
    """The X and Y limits a LinuxCNC configuration plans a circle with, in SI.

    Attributes
    ----------
    max_velocity_m_s : tuple of 2 float
        ``[AXIS_X]`` and ``[AXIS_Y]`` ``MAX_VELOCITY``. [m/s]
    max_accel_m_s2 : tuple of 2 float
        ``[AXIS_X]`` and ``[AXIS_Y]`` ``MAX_ACCELERATION``. [m/s^2]
    max_linear_velocity_m_s : float
        ``[TRAJ] MAX_LINEAR_VELOCITY``; infinite when not set. [m/s]
    source : str
        The INI file.
    """

    max_velocity_m_s: tuple
    max_accel_m_s2: tuple
    max_linear_velocity_m_s: float
    source: str

    @property
    def max_feed_m_s(self):
        """Fastest feed of an arc in the XY plane. [m/s]"""
        return min(*self.max_velocity_m_s, self.max_linear_velocity_m_s)

    @property
    def arc_accel_m_s2(self):
        """Largest normal acceleration of an arc: sqrt(3)/2 of the smaller axis limit. [m/s^2]"""
        return ARC_NORMAL_SHARE * min(self.max_accel_m_s2)

    def arc_feed_m_s(self, radius_m):
        """The speed LinuxCNC runs a circle of this radius at, when asked for more. [m/s]

        Parameters
        ----------
        radius_m : float
            Circle radius. [m]
        """
        return min(self.max_feed_m_s, math.sqrt(self.arc_accel_m_s2 * radius_m))

    def as_dict(self):
        """JSON-ready, in the units machinists use (mm/min, m/s^2)."""
        return {
            "ini": self.source,
            "max_velocity_mm_per_min": [v * 6e4 for v in self.max_velocity_m_s],
            "max_accel_m_s2": list(self.max_accel_m_s2),
            "max_linear_velocity_mm_per_min": self.max_linear_velocity_m_s * 6e4,
            "arc_accel_m_s2": self.arc_accel_m_s2,
        }


def read_limits(path):
    """The X and Y limits in a LinuxCNC INI file.

    Parameters
    ----------
    path : str or Path
        The machine's INI file.

    Returns
    -------
    ControllerLimits

    Raises
    ------
    ConfigError
        Naming the file, section and key: a missing or non-positive limit, or
        ``[TRAJ] LINEAR_UNITS`` other than mm or inch.
    """
    sections = read_ini(path)
    units = _value(sections, path, "TRAJ", "LINEAR_UNITS")
    if units.lower() not in _LINEAR_UNITS:
        raise ConfigError(
            f"{path}: [TRAJ] LINEAR_UNITS must be one of {sorted(_LINEAR_UNITS)}, got {units!r}"
        )
    scale = _LINEAR_UNITS[units.lower()]
    velocity = tuple(scale * _positive(sections, path, f"AXIS_{a}", "MAX_VELOCITY") for a in "XY")
    accel = tuple(scale * _positive(sections, path, f"AXIS_{a}", "MAX_ACCELERATION") for a in "XY")
    linear = math.inf
    if sections.get("TRAJ", {}).get("MAX_LINEAR_VELOCITY"):
        linear = scale * _positive(sections, path, "TRAJ", "MAX_LINEAR_VELOCITY")
    return ControllerLimits(velocity, accel, linear, str(path))
