"""What every alert sink shares: the monitor's states, the alert, and how a sink fails.

The alert that every sink sends is one JSON object::

    {"schema": "imu-square.alert/1",
     "alert_id": "3f0c...",              # the same on every retry: receivers dedupe on it
     "machine_id": "mill-3",
     "state": "alarm",                   # one of STATES
     "verdict": "changed by +14 ± 3 µm/m: check the machine",
     "created_at": "2026-10-03T02:14:05.120000+00:00",
     "record": {...}}                    # the run's record, as the monitor gives it

Non-finite numbers in the record (NaN, ±inf) become ``null``, so that every
JSON parser reads the body.
"""

import datetime as dt
import json
import math
import re
import uuid
from dataclasses import dataclass, field
from pathlib import PurePath

from imu_square.validation import check_option

STATES = ("ok", "warning", "alarm", "invalid", "stale_baseline", "no_baseline")
# A sink's default: everything a person must act on, not the nightly "ok".
DEFAULT_ALERT_STATES = ("warning", "alarm", "invalid", "stale_baseline")
ALERT_SCHEMA = "imu-square.alert/1"

_CONTROL_RUN = re.compile(r"[\x00-\x1f\x7f\x85\u2028\u2029]+")


def one_line(text):
    """``text`` with every run of control characters (CR, LF, NUL, tab...) made one space.

    Used on everything that ends up in a mail header or a log line, so a
    machine id or verdict holding ``"\\r\\nBcc: ..."`` cannot add a header or
    forge a log line.

    Parameters
    ----------
    text : str
        Any text.

    Returns
    -------
    str
    """
    return _CONTROL_RUN.sub(" ", text)


def json_ready(value, where="record"):
    """A deep copy of ``value`` that :func:`json.dumps` takes with ``allow_nan=False``.

    Dicts, lists, tuples, strings, booleans, integers and None pass; floats
    pass unless non-finite (then None); numpy scalars become Python numbers;
    paths become strings; datetimes their ISO 8601 text.

    Parameters
    ----------
    value : object
        The run's record or one of its items.
    where : str
        Position in the record, for the message.

    Returns
    -------
    object

    Raises
    ------
    TypeError
        For any other type (a programming error in the caller, not a user's).
    """
    if value is None or isinstance(value, bool | int | str):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        out = {}
        for key, item in value.items():
            if not isinstance(key, str):
                raise TypeError(f"{where}: keys must be strings, got {key!r}")
            out[key] = json_ready(item, f"{where}.{key}")
        return out
    if isinstance(value, list | tuple):
        return [json_ready(item, f"{where}[{i}]") for i, item in enumerate(value)]
    if isinstance(value, PurePath):
        return str(value)
    if isinstance(value, dt.datetime | dt.date):
        return value.isoformat()
    if hasattr(value, "item") and hasattr(value, "dtype"):  # numpy scalar
        return json_ready(value.item(), where)
    raise TypeError(f"{where}: cannot be sent as JSON: {type(value).__name__} {value!r}")


@dataclass(frozen=True)
class Alert:
    """One night's verdict as the sinks send it.

    Build one with :func:`make_alert`; :meth:`from_dict` reads one back from
    the outbox.

    Attributes
    ----------
    alert_id : str
        Random hex id, the same on every retry and in every sink.
    machine_id : str
        The machine, as the monitor file names it.
    state : str
        One of :data:`STATES`.
    verdict : str
        The one-line verdict shown to people.
    created_at : str
        When the alert was made, ISO 8601 in UTC.
    record : dict
        The run's record, JSON-ready.
    """

    alert_id: str
    machine_id: str
    state: str
    verdict: str
    created_at: str
    record: dict = field(default_factory=dict)

    def as_dict(self):
        """The alert as the JSON object every sink sends (module docstring)."""
        return {
            "schema": ALERT_SCHEMA,
            "alert_id": self.alert_id,
            "machine_id": self.machine_id,
            "state": self.state,
            "verdict": self.verdict,
            "created_at": self.created_at,
            "record": self.record,
        }

    def to_json(self, indent=None):
        """The alert as UTF-8 JSON bytes (non-ASCII kept as is)."""
        text = json.dumps(self.as_dict(), ensure_ascii=False, allow_nan=False, indent=indent)
        return text.encode("utf-8")

    @classmethod
    def from_dict(cls, d):
        """Read back what :meth:`as_dict` wrote.

        Raises
        ------
        ValueError
            If ``d`` is not an alert of this schema.
        """
        if not isinstance(d, dict) or d.get("schema") != ALERT_SCHEMA:
            raise ValueError(f"not an {ALERT_SCHEMA} object")
        try:
            return cls(
                alert_id=str(d["alert_id"]),
                machine_id=str(d["machine_id"]),
                state=str(d["state"]),
                verdict=str(d["verdict"]),
                created_at=str(d["created_at"]),
                record=dict(d["record"]),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"malformed alert: {exc!r}") from None

    @property
    def created(self):
        """:attr:`created_at` as an aware datetime."""
        return dt.datetime.fromisoformat(self.created_at)


def make_alert(record, *, machine_id, state, verdict, now=None):
    """Make the alert for one run.

    Parameters
    ----------
    record : dict
        The run's record (JSON-ready, see :func:`json_ready`).
    machine_id : str
        The machine's id.
    state : str
        One of :data:`STATES`.
    verdict : str
        The one-line verdict.
    now : datetime, optional
        Creation time (aware); the current time by default.

    Returns
    -------
    Alert
    """
    check_option("state", state, STATES)
    now = dt.datetime.now(dt.UTC) if now is None else now.astimezone(dt.UTC)
    return Alert(
        alert_id=uuid.uuid4().hex,
        machine_id=str(machine_id),
        state=state,
        verdict=str(verdict),
        created_at=now.isoformat(timespec="microseconds"),
        record=json_ready(record),
    )


class DeliveryError(Exception):
    """A sink could not deliver an alert.

    Parameters
    ----------
    message : str
        What went wrong, for the log and the outcome.
    permanent : bool
        True for a configuration error that retrying cannot fix (HTTP 4xx,
        a refused login, a certificate that does not verify, a missing
        secret); False for a failure that may pass (server down, timeout,
        HTTP 5xx, SMTP 4xx).
    retry_after_s : float, optional
        The server's own ``Retry-After``. [s]
    """

    def __init__(self, message, permanent=False, retry_after_s=None):
        super().__init__(message)
        self.permanent = permanent
        self.retry_after_s = retry_after_s
