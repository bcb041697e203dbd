"""When a recording started: a date a person gives, and the earliest date taken as one.

A sensor board's or a logger's clock may count from its own power-on: its
times are then seconds, not a date, and a recording dated 1970 would be judged
against the wrong baseline. Times before :data:`EARLIEST_NS` are taken as such
a relative clock.
"""

from datetime import UTC, datetime, timedelta

from imu_square.errors import ImuSquareError

_EPOCH = datetime(1970, 1, 1, tzinfo=UTC)
#: 2000-01-01T00:00:00Z: a recording's time before this is no date. [ns]
EARLIEST_NS = 946_684_800 * 1_000_000_000


def is_date(time_ns):
    """Whether a recording time is a date (not before 2000), not a relative clock.

    Parameters
    ----------
    time_ns : int
        Nanoseconds since the Unix epoch. [ns]

    Returns
    -------
    bool
    """
    return int(time_ns) >= EARLIEST_NS


def parse_start_time(text, name="--start-time"):
    """Nanoseconds since the Unix epoch of an ISO 8601 date and time with its zone.

    Parameters
    ----------
    text : str
        For example ``2026-09-01T02:30:00Z`` or ``2026-09-01 04:30:00.250+02:00``.
    name : str
        The option or field, for the message.

    Returns
    -------
    int
        The time, UTC. [ns]

    Raises
    ------
    ImuSquareError
        Not such a time, no time zone, or before 2000.
    """
    try:
        when = datetime.fromisoformat(str(text).strip())
    except ValueError:
        raise ImuSquareError(
            f"{name} must be a date and time like 2026-09-01T02:30:00Z, got {text!r}"
        ) from None
    if when.utcoffset() is None:
        raise ImuSquareError(
            f"{name} must say its time zone (Z for UTC, or an offset such as +02:00), got {text!r}"
        )
    ns = (when - _EPOCH) // timedelta(microseconds=1) * 1000
    if not is_date(ns):
        raise ImuSquareError(f"{name} must be in 2000 or later, got {text!r}")
    return ns
