"""Reading machine and sensor description files (TOML): checked fields, unit conversion.

A description file is a set of sections; each field has a unit in its name
(``tau_x_ms``, ``x_um``, ...). Unknown sections and fields are errors, so a typo
never silently leaves an effect off.
"""

import math
import tomllib

from imu_square.errors import ConfigError
from imu_square.textfile import read_text
from imu_square.validation import check_option


def load_toml(path):
    """Read a TOML file into a dict, raising ConfigError naming the file.

    Parameters
    ----------
    path : str or Path
        The file.

    Returns
    -------
    dict
    """
    text = read_text(path, ConfigError)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None


class Sections:
    """Checked access to the sections of one description file.

    Parameters
    ----------
    doc : dict
        The parsed TOML.
    source : str
        File name, for messages.
    layout : dict of str to dict
        Allowed sections and, for each, its allowed fields with defaults.
    """

    def __init__(self, doc, source, layout):
        self.source = source
        self.layout = layout
        unknown = sorted(set(doc) - set(layout))
        if unknown:
            raise ConfigError(
                f"{source}: unknown section [{unknown[0]}]; allowed: {sorted(layout)}"
            )
        self.doc = {}
        for name, table in doc.items():
            if not isinstance(table, dict):
                raise ConfigError(f"{source}: [{name}] must be a table, got {table!r}")
            bad = sorted(set(table) - set(layout[name]))
            if bad:
                raise ConfigError(
                    f"{source}: [{name}] has unknown field {bad[0]!r}; "
                    f"allowed: {sorted(layout[name])}"
                )
            self.doc[name] = table

    def has(self, section):
        """Whether the file has ``section``."""
        return section in self.doc

    def raw(self, section, key):
        """The field's value as written, or its default."""
        return self.doc.get(section, {}).get(key, self.layout[section][key])

    def number(
        self, section, key, scale=1.0, lo=-math.inf, hi=math.inf, lo_open=False, hi_open=False
    ):
        """A finite number in [lo, hi] (ends excluded if open), times ``scale``.

        Parameters
        ----------
        section, key : str
            Where the field is.
        scale : float
            Factor from the file's unit to SI.
        lo, hi : float
            Allowed range in the file's unit.
        lo_open, hi_open : bool
            Whether ``lo`` or ``hi`` itself is excluded.

        Returns
        -------
        float
        """
        value = self.raw(section, key)
        where = f"{self.source}: [{section}] {key}"
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{where} must be a number, got {value!r}")
        value = float(value)
        low_ok = value > lo if lo_open else value >= lo
        high_ok = value < hi if hi_open else value <= hi
        if not (math.isfinite(value) or value == hi == math.inf) or not (low_ok and high_ok):
            interval = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
            raise ConfigError(f"{where} must be in {interval}, got {value!r}")
        return value * scale

    def pair(self, section, key, scale=1.0):
        """Two finite numbers ``[a, b]``, times ``scale``."""
        value = self.raw(section, key)
        where = f"{self.source}: [{section}] {key}"
        if (
            not isinstance(value, list)
            or len(value) != 2
            or any(isinstance(v, bool) or not isinstance(v, int | float) for v in value)
            or not all(math.isfinite(v) for v in value)
        ):
            raise ConfigError(f"{where} must be two finite numbers [a, b], got {value!r}")
        return (float(value[0]) * scale, float(value[1]) * scale)

    def flag(self, section, key):
        """A boolean field."""
        value = self.raw(section, key)
        if not isinstance(value, bool):
            raise ConfigError(
                f"{self.source}: [{section}] {key} must be true or false, got {value!r}"
            )
        return value

    def choice(self, section, key, allowed):
        """A string field, one of ``allowed``."""
        return check_option(
            f"[{section}] {key}", self.raw(section, key), allowed, self.source, ConfigError
        )

    def text(self, section, key):
        """A string field."""
        value = self.raw(section, key)
        if not isinstance(value, str):
            raise ConfigError(f"{self.source}: [{section}] {key} must be a string, got {value!r}")
        return value
