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
import os
import re
import ssl
import uuid
from dataclasses import dataclass, field

from imu_square.json_values import json_safe
from imu_square.monitor.history.rows import EVALUATION_STATES as STATES  # the verdicts'
from imu_square.validation import check_option

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


@dataclass(frozen=True)
class Alert:
    """One night's verdict as the sinks send it.

    Build one with :func:`make_alert`; :func:`~imu_square.json_values.from_json`
    reads one back from :meth:`as_dict`.

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
        return {"schema": ALERT_SCHEMA, **json_safe(self)}

    def to_json(self, indent=None):
        """The alert as UTF-8 JSON bytes (non-ASCII kept as is)."""
        text = json.dumps(self.as_dict(), ensure_ascii=False, allow_nan=False, indent=indent)
        return text.encode("utf-8")

    @property
    def created(self):
        """:attr:`created_at` as an aware datetime."""
        return dt.datetime.fromisoformat(self.created_at)


def make_alert(record, *, machine_id, state, verdict, now=None):
    """Make the alert for one run.

    Parameters
    ----------
    record : dict
        The run's record (made JSON-safe by
        :func:`~imu_square.json_values.json_safe`).
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
        record=json_safe(record, "record"),
    )


def env_secret(variable, field):
    """A secret from the environment, read when an alert is sent (never stored).

    Parameters
    ----------
    variable : str
        The environment variable.
    field : str
        The sink's field that names it, for the message.

    Returns
    -------
    str

    Raises
    ------
    DeliveryError
        Permanent, when the variable is not set or empty.
    """
    value = os.environ.get(variable, "")
    if not value:
        raise DeliveryError(
            f"the environment variable {variable} ({field}) is not set", permanent=True
        )
    return value


def tls_context(ca_file):
    """A TLS context that verifies the server against the system's CAs or ``ca_file``.

    Parameters
    ----------
    ca_file : Path or None
        A CA bundle to use instead of the system's.

    Returns
    -------
    ssl.SSLContext

    Raises
    ------
    DeliveryError
        Permanent, when ``ca_file`` cannot be loaded.
    """
    try:
        return ssl.create_default_context(cafile=ca_file)
    except (OSError, ssl.SSLError) as exc:
        raise DeliveryError(f"cannot load ca_file {ca_file}: {exc}", permanent=True) from None


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
