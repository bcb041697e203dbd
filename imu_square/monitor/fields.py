"""Checked access to one table of the monitor file.

Every check raises :class:`~imu_square.errors.MonitorConfigError` with one line
naming the file, the table, the field, what is allowed and the value received,
e.g. ``monitor.toml: [[alerts.webhook]] #2 timeout_s must be in (0, 120], got 0``.
Unknown fields are errors, so a typo never silently leaves a sink unconfigured.
"""

import math
import re
import unicodedata
from pathlib import Path

from imu_square.errors import MonitorConfigError

REQUIRED = object()  # default meaning "the field must be given"

_ENV_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def has_control_chars(text):
    """Whether ``text`` holds a control character (CR, LF, NUL, ...; not a plain space).

    Parameters
    ----------
    text : str
        Any text.

    Returns
    -------
    bool
    """
    return any(unicodedata.category(c) in ("Cc", "Zl", "Zp") for c in text)


class Table:
    """One TOML table of the monitor file, with typed, range-checked fields.

    Parameters
    ----------
    table : object
        The parsed TOML value; anything but a dict is an error.
    where : str
        The table as the user wrote it, for messages (``"[alerts.email]"``).
    allowed : iterable of str
        The field names this table may hold.
    source : str
        The monitor file's name, for messages.
    base_dir : str or Path, optional
        Folder that relative paths are resolved against (the monitor file's
        folder); None keeps them relative to the working directory.
    """

    def __init__(self, table, where, allowed, source, base_dir=None):
        self.where = where
        self.source = source
        self.base_dir = None if base_dir is None else Path(base_dir)
        if not isinstance(table, dict):
            raise MonitorConfigError(f"{source}: {where} must be a table, got {table!r}")
        unknown = sorted(set(table) - set(allowed))
        if unknown:
            raise MonitorConfigError(
                f"{source}: {where} has unknown field {unknown[0]!r}; allowed: {sorted(allowed)}"
            )
        self.table = table

    def fail(self, key, allowed, value):
        """Raise the one-line error: field ``key`` must be ``allowed``, got ``value``."""
        self.error(f"{key} must be {allowed}, got {value!r}")

    def error(self, text):
        """Raise a one-line error about this table: ``FILE: [TABLE] text``."""
        raise MonitorConfigError(f"{self.source}: {self.where} {text}")

    def has(self, key):
        """Whether the field is written in the file."""
        return key in self.table

    def get(self, key, default):
        """The field's value as written, its default, or an error if it is required."""
        if key in self.table:
            return self.table[key]
        if default is REQUIRED:
            raise MonitorConfigError(
                f"{self.source}: {self.where} is missing the required field {key!r}"
            )
        return default

    def text(self, key, default=REQUIRED, empty=False):
        """A one-line string (no control characters).

        Parameters
        ----------
        key : str
            Field name.
        default : str or None or REQUIRED
            Value when the field is absent.
        empty : bool
            Whether the empty string is allowed.

        Returns
        -------
        str or None
        """
        value = self.get(key, default)
        if value is None:  # absent with a None default: TOML itself has no null
            return None
        if not isinstance(value, str) or (not empty and not value) or has_control_chars(value):
            what = "a string" if empty else "a non-empty string"
            self.fail(key, f"{what} on one line (no control characters)", value)
        return value

    def number(self, key, default, lo, hi, lo_open=False):
        """A finite number in ``[lo, hi]`` (or ``(lo, hi]`` if ``lo_open``).

        Parameters
        ----------
        key : str
            Field name.
        default : float or REQUIRED
            Value when the field is absent.
        lo, hi : float
            Allowed range, in the field's own unit (named in its key).
        lo_open : bool
            Whether ``lo`` itself is excluded.

        Returns
        -------
        float
        """
        value = self.get(key, default)
        interval = f"{'(' if lo_open else '['}{lo:g}, {hi:g}]"
        if isinstance(value, bool) or not isinstance(value, int | float):
            self.fail(key, f"a number in {interval}", value)
        ok = (value > lo if lo_open else value >= lo) and value <= hi
        if not (math.isfinite(value) and ok):
            self.fail(key, f"in {interval}", value)
        return float(value)

    def integer(self, key, default, lo, hi):
        """A whole number in ``[lo, hi]``."""
        value = self.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
            self.fail(key, f"a whole number in [{lo}, {hi}]", value)
        return value

    def choice(self, key, default, allowed):
        """One of ``allowed``."""
        value = self.get(key, default)
        if value not in allowed:
            self.fail(key, f"one of {tuple(allowed)!r}", value)
        return value

    def choices(self, key, default, allowed, empty=True):
        """A list of distinct values, each one of ``allowed``, as a tuple.

        Parameters
        ----------
        key : str
            Field name.
        default : tuple or REQUIRED
            Value when the field is absent.
        allowed : tuple of str
            The values the list may hold.
        empty : bool
            Whether the empty list is allowed.

        Returns
        -------
        tuple of str
        """
        value = self.get(key, default)
        if (
            not isinstance(value, list | tuple)
            or (not empty and not value)
            or any(v not in allowed for v in value)
            or len(set(value)) != len(value)
        ):
            self.fail(key, f"a list of distinct values from {tuple(allowed)!r}", value)
        return tuple(value)

    def env_name(self, key):
        """The name of an environment variable (letters, digits, ``_``), or None if absent."""
        value = self.get(key, None)
        if value is None:
            return None
        if not isinstance(value, str) or not _ENV_NAME.fullmatch(value):
            self.fail(key, "an environment variable name ([A-Za-z_][A-Za-z0-9_]*)", value)
        return value

    def path(self, key, default=REQUIRED):
        """A file path: ``~`` expanded, relative paths resolved against ``base_dir``.

        Returns
        -------
        Path or None
            None only when the field is absent and ``default`` is None.
        """
        value = self.text(key, default)
        if value is None:
            return None
        path = Path(value).expanduser()
        if not path.is_absolute() and self.base_dir is not None:
            path = self.base_dir / path
        return path


def tables(value, where, source):
    """A sink section written as one table (``[x]``) or an array of tables (``[[x]]``).

    Parameters
    ----------
    value : object
        The parsed TOML value.
    where : str
        Dotted name of the section, e.g. ``"alerts.webhook"``.
    source : str
        The monitor file's name, for messages.

    Returns
    -------
    list of (dict, str)
        Each table with its label for messages: ``"[alerts.email]"`` for a
        single table, ``"[[alerts.webhook]] #2"`` for the second of an array.
    """
    if isinstance(value, dict):
        return [(value, f"[{where}]")]
    if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        return [(v, f"[[{where}]] #{i}") for i, v in enumerate(value, start=1)]
    raise MonitorConfigError(
        f"{source}: [{where}] must be a table or an array of tables ([[{where}]]), got {value!r}"
    )
