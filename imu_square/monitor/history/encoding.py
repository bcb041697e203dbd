"""How values go into the history and come out: canonical JSON, keys, times, messages.

- :func:`canonical_json` writes JSON with sorted keys, no spaces, ASCII only
  and finite numbers, so equal values give equal text on every backend;
- :func:`settings_hash` and :func:`file_sha256` are the two halves of a run's
  key besides the machine: the analysis settings and the recording's bytes;
- times are integer nanoseconds since the Unix epoch, UTC, like MCAP's.
"""

import hashlib
import json
from datetime import UTC, datetime, timedelta

from imu_square.errors import HistoryError, RecordingError
from imu_square.json_values import json_safe

_EPOCH = datetime(1970, 1, 1, tzinfo=UTC)


def canonical_json(value, name="value"):
    """The canonical JSON text of ``value``: sorted keys, no spaces, ASCII, finite numbers.

    Parameters
    ----------
    value : object
        JSON values by :func:`~imu_square.json_values.json_safe`'s rules
        (non-finite floats are written as null).
    name : str
        What ``value`` is, for the error message.

    Returns
    -------
    str
        The JSON text; equal values give equal text.
    """
    return json.dumps(
        json_safe(value, name),
        sort_keys=True,
        separators=(",", ":"),
        ensure_ascii=True,
        allow_nan=False,
    )


def settings_hash(settings):
    """SHA-256 of the analysis settings' canonical JSON: the runs' settings key.

    Parameters
    ----------
    settings : dict
        The analysis settings, as JSON values (see :func:`canonical_json`).

    Returns
    -------
    str
        64 lower-case hexadecimal digits.
    """
    return hashlib.sha256(canonical_json(settings, "settings").encode("utf-8")).hexdigest()


def file_sha256(path):
    """SHA-256 of a recording's bytes: the runs' recording key.

    Parameters
    ----------
    path : str or Path
        The recording.

    Returns
    -------
    str
        64 lower-case hexadecimal digits.
    """
    try:
        with open(path, "rb") as f:
            return hashlib.file_digest(f, "sha256").hexdigest()
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read the recording: {exc.strerror}") from None


def ns_from_datetime(when):
    """Integer nanoseconds since the Unix epoch of an aware datetime.

    Parameters
    ----------
    when : datetime
        A time with its time zone.

    Returns
    -------
    int
        Nanoseconds since 1970-01-01T00:00:00Z. [ns]
    """
    if not isinstance(when, datetime) or when.utcoffset() is None:
        raise HistoryError(f"a time must be a datetime with its time zone, got {when!r}")
    return (when - _EPOCH) // timedelta(microseconds=1) * 1000


def datetime_from_ns(ns):
    """The UTC datetime of integer nanoseconds since the Unix epoch (to the microsecond).

    Parameters
    ----------
    ns : int or None
        Nanoseconds since 1970-01-01T00:00:00Z. [ns]

    Returns
    -------
    datetime or None
        Aware, in UTC; None for None.
    """
    if ns is None:
        return None
    return _EPOCH + timedelta(microseconds=ns // 1000)


def now_ns():
    """The current UTC time in integer nanoseconds since the Unix epoch. [ns]"""
    return ns_from_datetime(datetime.now(UTC))


def first_line(exc):
    """The first non-empty line of an exception's message (drivers' messages run on)."""
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    return lines[0] if lines else type(exc).__name__
