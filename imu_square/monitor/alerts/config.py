"""The ``[alerts]`` section of the monitor file: which sinks, which states, how hard to retry.

Every field is optional; without an ``[alerts]`` section the monitor only
logs. A full section::

    [alerts]
    states = ["warning", "alarm", "invalid", "stale_baseline"]  # default of every sink but the log
    attempts = 4          # tries per sink and alert, the first included
    backoff_s = 0.5       # wait before the second try; doubles each time (50-100 % jitter)
    max_total_s = 10.0    # cap on one delivery round of one sink (the sinks go one after the other)

    [alerts.log]
    states = ["ok", "warning", "alarm", "invalid", "stale_baseline", "no_baseline"]

    [alerts.json_file]                # or [[alerts.json_file]] for several
    path = "/var/lib/imu-square/latest-alert.json"
    mode = "latest"                   # or "append" (JSON Lines)

    [[alerts.webhook]]                # one [[alerts.webhook]] per URL
    url = "https://hooks.example.com/imu-square"   # or url_env = "VAR" when the URL is a secret
    timeout_s = 5.0
    headers = { "X-Shop" = "hall 2" }
    token_env = "IMU_SQUARE_WEBHOOK_TOKEN"         # sent as "Authorization: Bearer $TOKEN"
    states = ["ok", "warning", "alarm", "invalid", "stale_baseline", "no_baseline"]

    [alerts.email]                    # or [[alerts.email]] for several
    host = "smtp.example.com"
    security = "starttls"             # "ssl" or "none"; port 587, 465 or 25 unless given
    sender = "imu-square <noreply@example.com>"
    to = ["maint@example.com"]
    username = "imu-square"
    password_env = "IMU_SQUARE_SMTP_PASSWORD"      # or password_file = "/etc/imu-square/smtp"

Every sink table may also set ``name`` (letters, digits, ``_.-``), the name it
has in outcomes, logs and the outbox; by default ``json_file``, ``webhook``
and ``email``, numbered ``webhook-1``, ``webhook-2``... when there are several.
Relative paths are taken from the monitor file's folder. The pending alerts
are kept in the history (:mod:`imu_square.monitor.history.outbox`); the field
``outbox`` of older monitor files, their folder, is read with a warning and
not used.
"""

import re
import warnings
from dataclasses import dataclass, fields

from imu_square.errors import ImuSquareWarning, MonitorConfigError
from imu_square.monitor.alerts.alert import DEFAULT_ALERT_STATES, STATES
from imu_square.monitor.alerts.json_file import JsonFileSink, json_file_from_table
from imu_square.monitor.alerts.log_line import LogSink, log_from_table
from imu_square.monitor.alerts.mail import EmailSink, email_from_table
from imu_square.monitor.alerts.webhook import WebhookSink, webhook_from_table
from imu_square.validation import TomlTable, tables

ALERTS_FIELDS = ("states", "attempts", "backoff_s", "max_total_s", "outbox")
# Each kind's sink and its builder; a sink's table has the sink's fields.
SINK_KINDS = {
    "json_file": (JsonFileSink, json_file_from_table),
    "webhook": (WebhookSink, webhook_from_table),
    "email": (EmailSink, email_from_table),
}
_SINK_NAME = re.compile(r"[A-Za-z0-9_.-]{1,64}")


@dataclass(frozen=True)
class RetryPolicy:
    """How hard one delivery round tries.

    Attributes
    ----------
    attempts : int
        Tries per sink and alert, the first included.
    backoff_s : float
        Wait before the second try; it doubles before each later one, and
        each wait is drawn uniformly from 50-100 % of that (jitter, so that
        many machines do not retry in step). [s]
    max_total_s : float
        Cap on one round of one sink: no try starts, and no socket waits,
        past it. [s]
    """

    attempts: int = 4
    backoff_s: float = 0.5
    max_total_s: float = 10.0


@dataclass(frozen=True)
class AlertsConfig:
    """The validated ``[alerts]`` section.

    Attributes
    ----------
    sinks : tuple
        The log sink first, then JSON files, webhooks and e-mails, in file order.
    retry : RetryPolicy
        Retry and time-cap settings.
    """

    sinks: tuple = (LogSink(),)
    retry: RetryPolicy = RetryPolicy()

    def sink(self, name):
        """The sink called ``name``, or None."""
        return next((s for s in self.sinks if s.name == name), None)


def alerts_from_mapping(table, source="<monitor file>", base_dir=None):
    """Validate the ``[alerts]`` table of a loaded monitor file.

    Parameters
    ----------
    table : dict or None
        ``doc.get("alerts")`` of the parsed TOML; None gives the default (log only).
    source : str
        The monitor file's name, for messages.
    base_dir : str or Path, optional
        Folder that relative paths are taken from (the monitor file's folder).

    Returns
    -------
    AlertsConfig

    Raises
    ------
    MonitorConfigError
        One line naming the field, what is allowed and the value received.
    """
    if table is None:
        return AlertsConfig()

    def checked(value, where, fields):
        return TomlTable(value, where, fields, source, base_dir, MonitorConfigError)

    top = checked(table, "[alerts]", (*ALERTS_FIELDS, "log", *SINK_KINDS))
    default_states = top.choices("states", STATES, default=DEFAULT_ALERT_STATES)
    retry = RetryPolicy(
        attempts=top.integer("attempts", 1, 10, default=4),
        backoff_s=top.number("backoff_s", 0.0, 60.0, default=0.5),
        max_total_s=top.number("max_total_s", 0.0, 300.0, lo_open=True, default=10.0),
    )
    log = LogSink()
    if top.has("log"):
        log = log_from_table(checked(table["log"], "[alerts.log]", ("states",)))
    sinks = [log]
    for kind, (sink, build) in SINK_KINDS.items():
        if not top.has(kind):
            continue
        labelled = tables(table[kind], f"alerts.{kind}", source, MonitorConfigError)
        for i, (raw, where) in enumerate(labelled, start=1):
            t = checked(raw, where, [f.name for f in fields(sink)])
            name = t.text("name", default=kind if len(labelled) == 1 else f"{kind}-{i}")
            if not _SINK_NAME.fullmatch(name) or name == "log":
                t.fail("name", "1-64 letters, digits, '_', '.' or '-', and not 'log'", name)
            if any(s.name == name for s in sinks):
                t.fail("name", "different from every other sink's name", name)
            sinks.append(build(t, name, default_states))
    if top.has("outbox"):
        warnings.warn(
            f"{source}: [alerts] outbox is no longer used: the pending alerts are kept in "
            "the history; remove the field",
            ImuSquareWarning,
            stacklevel=2,
        )
    return AlertsConfig(sinks=tuple(sinks), retry=retry)
