"""Checking what users give: one message template and one rule per kind of value.

Plain functions in the manner of statsmodels' ``tools/validation`` and
MNE-Python's ``utils/check.py``: each takes the value and what is allowed, and
returns the value normalised (a float, an int, ...) or raises. Every refusal
is one line in one template::

    {where}: {name} must be {allowed}, got {value!r}

Every check takes ``name``, the parameter or the field as the user wrote it
(``"[alerts] backoff_s"``); ``where``, the file (left out for a Python
argument); and ``error``, the :class:`~imu_square.errors.ImuSquareError`
subclass to raise (or a callable that makes one from the message). ``kind``
and ``allowed``, where a check has them, replace its default wording for a
value of the wrong type and for one out of range.

The rules, the same for every file and every public function:

- a number is a real number: a Python or numpy int or float, or a 0-d array
  of one, never a bool (TOML's ``true`` is not 1.0). It is finite, unless an
  infinite bound is given closed (``hi=math.inf``). It is reported as the
  float it is read as;
- a whole number is a Python or numpy integer, never a bool or a float (TOML
  tells ``2`` from ``2.0``, and a float loses nanoseconds);
- text is a non-blank string with no control characters: it ends up in log
  lines, e-mail headers and file names.

:class:`TomlTable` reads one table of a TOML file with these checks; a field
it does not know is an error, so that a typo never silently leaves a setting
at its default.
"""

import math
import numbers
import re
import unicodedata
from pathlib import Path

from imu_square.errors import ImuSquareError

_REQUIRED = object()  # default meaning "the field must be given"
_FIELD = object()  # check the field's own value
_ENV_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def fail(name, allowed, value, where="", error=ImuSquareError):
    """Raise the one-line refusal: ``{where}: {name} must be {allowed}, got {value!r}``.

    Parameters
    ----------
    allowed : str
        What is allowed, e.g. ``"in (0, 1000]"``.
    value : object
        What was received.
    name, where, error
        See the module docstring.
    """
    prefix = f"{where}: " if where else ""
    raise error(f"{prefix}{name} must be {allowed}, got {value!r}")


def interval(lo=None, hi=None, lo_open=False, hi_open=False):
    """``[lo, hi]``, ``(lo, hi]`` and the like, for messages; None is an open infinity.

    An int bound is written in full, a float one with ``:g``.
    """

    def bound(x, inf):
        if x is None:
            return inf
        return str(x) if isinstance(x, int) else f"{x:g}"

    left = "(" if lo_open or lo is None else "["
    right = ")" if hi_open or hi is None else "]"
    return f"{left}{bound(lo, '-inf')}, {bound(hi, 'inf')}{right}"


def _plain(value):
    """A numpy scalar or 0-d array as the Python value it holds."""
    if getattr(value, "ndim", None) == 0 and hasattr(value, "item"):
        return value.item()
    return value


def is_number(value):
    """Whether ``value`` is what :func:`check_number` takes: a real number, not a bool."""
    value = _plain(value)
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def check_number(
    name,
    value,
    lo=None,
    hi=None,
    *,
    lo_open=False,
    hi_open=False,
    kind=None,
    allowed=None,
    where="",
    error=ImuSquareError,
):
    """A real number within ``[lo, hi]`` (ends excluded when open), as a float.

    Parameters
    ----------
    value : object
        What was given.
    lo, hi : float or None
        Bounds, in the value's own unit; None for none. An infinite bound
        given closed admits that infinity.
    lo_open, hi_open : bool
        Whether ``lo`` or ``hi`` itself is excluded.
    kind : str, optional
        Default ``"a number in [lo, hi]"``, or ``"a number"`` with no finite bound.
    allowed : str, optional
        Default ``"in [lo, hi]"``, or ``"finite"`` for NaN and an infinity
        the range does not admit.
    name, where, error
        See the module docstring.

    Returns
    -------
    float
    """
    span = interval(lo, hi, lo_open, hi_open)
    if not is_number(value):
        bounded = any(b is not None and math.isfinite(b) for b in (lo, hi))
        fail(name, kind or (f"a number in {span}" if bounded else "a number"), value, where, error)
    value = float(_plain(value))
    low = -math.inf if lo is None else lo
    high = math.inf if hi is None else hi
    above = value > low if lo_open else value >= low
    below = value < high if hi_open else value <= high
    # an infinity passes only as a bound the caller wrote
    if above and below and (math.isfinite(value) or value in (lo, hi)):
        return value
    admits_inf = (lo == -math.inf and not lo_open) or (hi == math.inf and not hi_open)
    finite = math.isfinite(value) or admits_inf
    fail(name, allowed or (f"in {span}" if finite else "finite"), value, where, error)


def check_int(
    name, value, lo=None, hi=None, *, kind=None, allowed=None, where="", error=ImuSquareError
):
    """A whole number within ``[lo, hi]`` (None: no bound), as an int.

    ``kind`` and ``allowed`` default to ``"a whole number in [lo, hi]"``
    (``kind`` to ``"a whole number"`` without bounds); ``name``, ``where`` and
    ``error`` are as in the module docstring.
    """
    ranged = f"a whole number in {interval(lo, hi)}"
    value = _plain(value)
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        unbounded = lo is None and hi is None
        fail(name, kind or ("a whole number" if unbounded else ranged), value, where, error)
    value = int(value)
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        fail(name, allowed or ranged, value, where, error)
    return value


def check_bool(name, value, *, kind="True or False", where="", error=ImuSquareError):
    """A bool (numpy's too); ``kind`` in the user's spelling (TOML's: ``"true or false"``)."""
    value = _plain(value)
    if not isinstance(value, bool):
        fail(name, kind, value, where, error)
    return value


def has_control_chars(text):
    """Whether ``text`` holds a control character (CR, LF, NUL, ...; not a plain space)."""
    return any(unicodedata.category(c) in ("Cc", "Zl", "Zp") for c in text)


def check_text(name, value, *, empty=False, controls=False, where="", error=ImuSquareError):
    """One line of text.

    Parameters
    ----------
    value : object
        What was given.
    empty : bool
        Whether an empty or blank string is allowed.
    controls : bool
        Whether control characters other than CR and LF are allowed (a file
        name stored as it was given may hold a tab).
    name, where, error
        See the module docstring.

    Returns
    -------
    str
    """
    if controls:
        ok = isinstance(value, str) and "\n" not in value and "\r" not in value
        what = "one line of text"
    else:
        ok = isinstance(value, str) and not has_control_chars(value)
        what = f"a {'' if empty else 'non-empty '}string on one line (no control characters)"
    if not ok or not (empty or value.strip()):
        fail(name, what, value, where, error)
    return value


def check_option(name, value, allowed, where="", error=ImuSquareError):
    """One of ``allowed``, returned unchanged: the one "must be one of" message.

    After MNE-Python's ``_check_option(parameter, value, allowed_values)``.
    """
    allowed = tuple(allowed)
    if value not in allowed:
        fail(name, f"one of {allowed!r}", value, where, error)
    return value


def check_sections(doc, allowed, source, error=ImuSquareError):
    """Refuse a section of the parsed TOML file ``doc`` that is not one of ``allowed``."""
    unknown = sorted(set(doc) - set(allowed))
    if unknown:
        raise error(f"{source}: unknown section [{unknown[0]}]; allowed: {sorted(allowed)}")


def read_tables(doc, layout, source, error=ImuSquareError, terse=False):
    """Every table of a TOML file made of known sections, checked.

    Parameters
    ----------
    doc : dict
        The parsed file.
    layout : dict of str to dict
        Each section's fields with their defaults.
    source : str
        The file, for messages.
    error : callable
        The error to raise.
    terse : bool
        See :class:`TomlTable`.

    Returns
    -------
    dict of str to TomlTable
        One per section of ``layout``; a section the file leaves out is an
        empty table, so that its fields take their defaults.
    """
    check_sections(doc, layout, source, error)
    return {
        name: TomlTable(doc.get(name, {}), f"[{name}]", fields, source, error=error, terse=terse)
        for name, fields in layout.items()
    }


def tables(value, where, source, error=ImuSquareError):
    """A section written as one table (``[x]``) or an array of tables (``[[x]]``).

    Parameters
    ----------
    value : object
        The parsed TOML value.
    where : str
        Dotted name of the section, e.g. ``"alerts.webhook"``.
    source : str
        The file, for messages.
    error : callable
        The error to raise.

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
    fail(f"[{where}]", f"a table or an array of tables ([[{where}]])", value, source, error)


class TomlTable:
    """One table of a TOML file, with typed, range-checked fields.

    Each getter takes the field's name (``key``) and a ``default`` for when the
    field is absent (else the table's default, else the field is required),
    and checks the value like the function it names.

    Parameters
    ----------
    table : object
        The parsed TOML value; anything but a dict is an error.
    where : str
        The table as the user wrote it, for messages (``"[alerts.email]"``).
    fields : iterable of str, or dict
        The field names the table may hold; a dict also gives their defaults.
    source : str
        The file's name, for messages.
    base_dir : str or Path, optional
        Folder that relative paths are resolved against (the file's folder);
        None keeps them relative to the working directory.
    error : callable
        The :class:`~imu_square.errors.ImuSquareError` subclass to raise.
    terse : bool
        Tell a value of the wrong type only its kind (``a number``), not the
        range: the wording the program, machine and sensor files have always
        had (the monitor file's is ``a number in [0, 60]``).
    """

    def __init__(
        self, table, where, fields, source, base_dir=None, error=ImuSquareError, terse=False
    ):
        self.where, self.source, self._error, self.terse = where, source, error, terse
        self.base_dir = None if base_dir is None else Path(base_dir)
        if not isinstance(table, dict):
            fail(where, "a table", table, source, error)
        self.table = table
        unknown = sorted(set(table) - set(fields))
        if unknown:
            self.error(f"has unknown field {unknown[0]!r}; allowed: {sorted(fields)}")
        self.defaults = fields if isinstance(fields, dict) else {}

    def _at(self, key):
        return {"name": f"{self.where} {key}", "where": self.source, "error": self._error}

    def fail(self, key, allowed, value):
        """Raise the one-line error: field ``key`` must be ``allowed``, got ``value``."""
        fail(allowed=allowed, value=value, **self._at(key))

    def error(self, text):
        """Raise a one-line error about this table: ``FILE: [TABLE] text``."""
        raise self._error(f"{self.source}: {self.where} {text}")

    def has(self, key):
        """Whether the field is written in the file."""
        return key in self.table

    def get(self, key, default=_REQUIRED):
        """The field's value as written, else its default, else an error: it is required."""
        if key in self.table:
            return self.table[key]
        if default is _REQUIRED:
            default = self.defaults.get(key, _REQUIRED)
        if default is _REQUIRED:
            self.error(f"is missing the required field {key!r}")
        return default

    def number(
        self,
        key,
        lo=None,
        hi=None,
        *,
        lo_open=False,
        hi_open=False,
        default=_REQUIRED,
        value=_FIELD,
    ):
        """:func:`check_number`, in the field's own unit (named in its key).

        ``value``, when given, is checked in the field's name instead of the
        field (one element of a list).
        """
        return check_number(
            value=self.get(key, default) if value is _FIELD else value,
            lo=lo,
            hi=hi,
            lo_open=lo_open,
            hi_open=hi_open,
            kind="a number" if self.terse else None,
            **self._at(key),
        )

    def numbers(self, key, sizes, what, lo=None, hi=None, *, lo_open=False, default=_REQUIRED):
        """A list of numbers as a tuple: its length one of ``sizes`` (the list is told
        ``what``), each number checked like :meth:`number`."""
        values = self.get(key, default)
        if not isinstance(values, list) or len(values) not in sizes:
            self.fail(key, what, values)
        return tuple(self.number(key, lo, hi, lo_open=lo_open, value=v) for v in values)

    def integer(self, key, lo=None, hi=None, *, default=_REQUIRED, value=_FIELD):
        """:func:`check_int`; ``value`` as in :meth:`number`."""
        return check_int(
            value=self.get(key, default) if value is _FIELD else value,
            lo=lo,
            hi=hi,
            kind="a whole number" if self.terse else None,
            **self._at(key),
        )

    def flag(self, key, *, default=_REQUIRED):
        """:func:`check_bool`."""
        return check_bool(value=self.get(key, default), kind="true or false", **self._at(key))

    def text(self, key, *, default=_REQUIRED, empty=False):
        """:func:`check_text`; None when absent with a None default (TOML has no null)."""
        value = self.get(key, default)
        return None if value is None else check_text(value=value, empty=empty, **self._at(key))

    def choice(self, key, allowed, *, default=_REQUIRED):
        """:func:`check_option`."""
        return check_option(value=self.get(key, default), allowed=allowed, **self._at(key))

    def choices(self, key, allowed, *, default=_REQUIRED):
        """A list of distinct values, each one of ``allowed``, as a tuple."""
        value = self.get(key, default)
        if (
            not isinstance(value, list | tuple)
            or any(v not in allowed for v in value)
            or len(set(value)) != len(value)
        ):
            self.fail(key, f"a list of distinct values from {tuple(allowed)!r}", value)
        return tuple(value)

    def env_name(self, key):
        """The name of an environment variable (letters, digits, ``_``), or None if absent."""
        value = self.get(key, None)
        if value is not None and not (isinstance(value, str) and _ENV_NAME.fullmatch(value)):
            self.fail(key, "an environment variable name ([A-Za-z_][A-Za-z0-9_]*)", value)
        return value

    def path(self, key, *, default=_REQUIRED):
        """A file path (Path, or None when absent with a None default): ``~`` expanded,
        a relative path taken from ``base_dir``."""
        value = self.text(key, default=default)
        if value is None:
            return None
        path = Path(value).expanduser()
        if not path.is_absolute() and self.base_dir is not None:
            path = self.base_dir / path
        return path
