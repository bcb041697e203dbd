"""Sending a night's alert to its sinks, through the outbox in the history.

:func:`queue_alert` makes the night's alert and keeps it in the history's
outbox (:mod:`imu_square.monitor.history.outbox`), one row for each sink
whose ``states`` hold tonight's state, in the transaction that stores the
night's run and verdict. Once that is committed, :func:`deliver_alerts`:

1. rejects the pending alerts of a sink that left the monitor file;
2. takes the sinks one after the other. For each, it first delivers what
   earlier runs left pending, oldest first, one try each, and stops at the
   sink's first failure for now (it is evidently down); then tonight's
   alert, up to ``attempts`` times with exponential back-off and jitter.
   Each of the two takes at most ``max_total_s``: no try starts past it,
   and socket timeouts are cut to the time left;
3. records each result in the outbox: delivered; still pending (retried at
   the next run); or rejected, when the sink refused the alert as a
   configuration error (HTTP 4xx, refused login, bad certificate, missing
   secret): logged, kept and not retried until it is queued again with
   ``include_rejected=True``, once the monitor file is fixed.

Each alert is claimed in the history before a sink is tried, so that two
monitor jobs never send it at the same moment. Delivery is at least once: a
receiver that must not see an alert twice dedupes on its ``alert_id``.

Nothing here runs a program or a shell; every configured string is used as
data (a URL, a header value, an address, a file path).
"""

import random
import time
import uuid
from dataclasses import asdict, dataclass

from imu_square.json_values import from_json
from imu_square.log import logger
from imu_square.monitor.alerts.alert import Alert, DeliveryError, make_alert
from imu_square.monitor.history.encoding import now_ns, ns_from_datetime
from imu_square.monitor.history.rows import OutboxRow

# What a round's result makes of an alert's row.
_ROW_STATE = {"sent": "delivered", "pending": "pending", "rejected": "rejected"}


@dataclass(frozen=True)
class SinkOutcome:
    """What became of one alert at one sink.

    Attributes
    ----------
    sink : str
        The sink's name.
    alert_id : str
        The alert.
    state : str
        The alert's state.
    status : str
        ``"sent"``; ``"skipped"`` (the sink does not take this state);
        ``"pending"`` (failed for now, or held by another process: kept in
        the outbox and retried at the next run); ``"rejected"`` (a
        configuration error, kept in the outbox and not retried).
    attempts : int
        Tries in this round.
    error : str or None
        The last failure.
    outbox_id : int or None
        The alert's row in the history's outbox, for ``pending`` and ``rejected``.
    """

    sink: str
    alert_id: str
    state: str
    status: str
    attempts: int = 0
    error: str | None = None
    outbox_id: int | None = None

    def as_dict(self):
        """The outcome as a JSON-ready dict."""
        return asdict(self)


@dataclass(frozen=True)
class AlertReport:
    """The result of :func:`deliver_alerts`.

    Attributes
    ----------
    alert : Alert or None
        Tonight's alert.
    outcomes : tuple of SinkOutcome
        Tonight's alert at each sink, in the configuration's order.
    backlog : tuple of SinkOutcome
        Earlier alerts from the outbox tried in this round.
    """

    alert: object
    outcomes: tuple
    backlog: tuple = ()

    @property
    def delivered(self):
        """Whether every sink that takes tonight's state has it."""
        return all(o.status in ("sent", "skipped") for o in self.outcomes)

    def as_dict(self):
        """The report as a JSON-ready dict (for the run's ``--json`` record)."""
        return {
            "alert_id": None if self.alert is None else self.alert.alert_id,
            "delivered": self.delivered,
            "outcomes": [o.as_dict() for o in self.outcomes],
            "backlog": [o.as_dict() for o in self.backlog],
        }


def sink_takes(sink, state, record):
    """Whether a sink takes a night's alert: its state, or a diagnostic in alarm.

    A diagnostic's own alarm (off by default: ``[diagnostics.alarms]``) goes
    where the squareness's alarms go, whatever the squareness's state.

    Parameters
    ----------
    sink : object
        A sink of the ``[alerts]`` section (its ``states``).
    state : str
        The alert's state (the squareness's).
    record : dict
        The night's record (its ``diagnostic_alarms``).

    Returns
    -------
    bool
    """
    return state in sink.states or bool(record.get("diagnostic_alarms") and "alarm" in sink.states)


def queue_alert(config, history, record, *, machine_id, state, verdict, now=None):
    """Make a night's alert and keep it in the outbox for each sink that takes its state.

    A night with a diagnostic in alarm (``record["diagnostic_alarms"]``) goes to
    the sinks that take ``alarm`` too, whatever the squareness's state: the
    alert's state stays the squareness's, its verdict and record name the
    diagnostic.

    Call it inside the transaction that stores the night, so that the night
    and its pending alerts land together; then :func:`deliver_alerts`.

    Parameters
    ----------
    config : AlertsConfig
        The ``[alerts]`` section.
    history : History
        The open history.
    record : dict
        The night's record (made JSON-safe by
        :func:`~imu_square.json_values.json_safe`).
    machine_id : str
        The machine's id.
    state : str
        One of :data:`~imu_square.monitor.alerts.alert.STATES`.
    verdict : str
        The one-line verdict.
    now : datetime, optional
        The alert's time (aware); the current time by default.

    Returns
    -------
    Alert
    """
    alert = make_alert(record, machine_id=machine_id, state=state, verdict=verdict, now=now)
    with history.transaction():
        for sink in config.sinks:
            if sink.kind != "log" and sink_takes(sink, state, record):  # the log: when sent
                history.add_alert(
                    OutboxRow(
                        machine_id=alert.machine_id,
                        alert_id=alert.alert_id,
                        sink=sink.name,
                        created_at_ns=ns_from_datetime(alert.created),
                        alert=alert.as_dict(),
                    )
                )
    return alert


def deliver_alerts(config, history, machine_id, alert=None, *, include_rejected=False, now=None):
    """Deliver a machine's pending alerts, and tonight's ``alert`` (module docstring).

    A sink's failure never raises: it is logged and reported in the
    outcomes, and the alert stays in the outbox.

    Parameters
    ----------
    config : AlertsConfig
        The ``[alerts]`` section.
    history : History
        The open history, outside any transaction.
    machine_id : str
        The machine whose alerts are delivered.
    alert : Alert, optional
        Tonight's alert, from :func:`queue_alert` (committed).
    include_rejected : bool
        First queue the rejected alerts again, after the monitor file is fixed.
    now : datetime, optional
        The time of this round (aware): claims are taken from it, and a
        claim left by a process that died runs out by it. The current time by
        default.

    Returns
    -------
    AlertReport

    Raises
    ------
    HistoryError
        If the history cannot be read or written (the alerts stay pending).
    """
    rounds = _Rounds(history, config.retry, now)
    if include_rejected:
        moved = history.requeue_rejected(machine_id)
        if moved:
            logger.info("alert outbox: %d rejected alert(s) of %s queued again", moved, machine_id)
    pending = history.outbox(machine_id)
    backlog = [rounds.orphan(r) for r in pending if config.sink(r.sink) is None]
    outcomes = []
    for sink in config.sinks:
        mine = [r for r in pending if r.sink == sink.name]
        tonight = [r for r in mine if alert is not None and r.alert_id == alert.alert_id]
        backlog += rounds.run(sink, [r for r in mine if r not in tonight], 1)
        if alert is None:
            continue
        if not sink_takes(sink, alert.state, alert.record):
            outcomes.append(SinkOutcome(sink.name, alert.alert_id, alert.state, "skipped"))
        elif sink.kind == "log":  # logging cannot fail in a way a retry would fix
            sink.deliver(alert)
            outcomes.append(SinkOutcome(sink.name, alert.alert_id, alert.state, "sent", 1))
        else:
            outcomes += rounds.run(sink, tonight, config.retry.attempts) or [
                SinkOutcome(
                    sink.name, alert.alert_id, alert.state, "pending", 0, "held by another process"
                )
            ]
    return AlertReport(alert, tuple(outcomes), tuple(b for b in backlog if b is not None))


def send_without_history(config, record, *, machine_id, state, verdict):
    """Send an alert straight to the sinks that take its state: the history cannot keep it.

    For a night the history could not take (busy, unreachable): there is no
    outbox to keep the alert in, so each sink gets its tries now, once.

    Parameters
    ----------
    config : AlertsConfig
        The ``[alerts]`` section.
    record : dict
        What the alert says (JSON values).
    machine_id, state, verdict : str
        As for :func:`queue_alert`.

    Returns
    -------
    AlertReport
    """
    alert = make_alert(record, machine_id=machine_id, state=state, verdict=verdict)
    outcomes = []
    for sink in (s for s in config.sinks if sink_takes(s, state, record)):
        deadline = time.monotonic() + config.retry.max_total_s
        result = _try(sink, alert, config.retry, deadline, config.retry.attempts)
        outcomes.append(SinkOutcome(sink.name, alert.alert_id, state, *result))
    return AlertReport(alert, tuple(outcomes), ())


class _Rounds:
    """One call's delivery rounds: its claim token and clock, the outbox's history."""

    def __init__(self, history, retry, now):
        self.history = history
        self.retry = retry
        self.claim = uuid.uuid4().hex
        self._start_ns = now_ns() if now is None else ns_from_datetime(now)
        self._start_s = time.monotonic()

    def _now_ns(self):
        return self._start_ns + int((time.monotonic() - self._start_s) * 1e9)

    def _take(self, row):
        # A round never tries past max_total_s, so a claim twice as long outlives it.
        at_ns = self._now_ns()
        until_ns = at_ns + int(2e9 * self.retry.max_total_s)
        return self.history.claim_alert(row.id, self.claim, until_ns, at_ns)

    def run(self, sink, rows, max_attempts):
        """Deliver ``rows`` to ``sink`` oldest first, in one round; stop at its first failure."""
        deadline = time.monotonic() + self.retry.max_total_s
        out, down = [], None
        for row in rows:
            alert = from_json(Alert, row.alert)
            if down is not None:
                error = f"not tried: {sink.name} failed on an earlier alert ({down})"
                out.append(
                    SinkOutcome(sink.name, row.alert_id, alert.state, "pending", 0, error, row.id)
                )
            elif self._take(row):  # else another process is delivering it
                status, attempts, error = _try(sink, alert, self.retry, deadline, max_attempts)
                out.append(self._settle(sink.name, row, alert.state, status, attempts, error))
                if status == "pending":
                    down = error
        return out

    def orphan(self, row):
        """Reject an alert whose sink is no longer in the monitor file."""
        if not self._take(row):
            return None
        error = f"the sink {row.sink!r} is no longer in the monitor file"
        return self._settle(row.sink, row, row.alert["state"], "rejected", 0, error)

    def _settle(self, name, row, state, status, attempts, error):
        if not self.history.settle_alert(row.id, self.claim, _ROW_STATE[status], attempts, error):
            logger.warning(
                "alert outbox: the claim on alert %s for %s ran out before its result was "
                "recorded; another run has it",
                row.alert_id,
                name,
            )
        if status == "pending":
            logger.warning("alert sink %s: alert kept in the outbox, retried at the next run", name)
        elif status == "rejected":
            logger.error(
                "alert sink %s refused the alert (a configuration error, not retried): %s; "
                "kept in the history's outbox until the monitor file is fixed and the alert "
                "queued again",
                name,
                error,
            )
        outbox_id = None if status == "sent" else row.id
        return SinkOutcome(name, row.alert_id, state, status, attempts, error, outbox_id)


def _try(sink, alert, retry, deadline, max_attempts):
    """Try a sink up to ``max_attempts`` times before ``deadline``; (status, attempts, error)."""
    attempts, error = 0, None
    wait_s = retry.backoff_s
    while True:
        left_s = deadline - time.monotonic()
        if left_s <= 0:
            return (
                "pending",
                attempts,
                error or f"no time left within max_total_s={retry.max_total_s:g}",
            )
        attempts += 1
        timeout_s = None if sink.timeout_s is None else min(sink.timeout_s, left_s)
        retry_after_s = None
        try:
            sink.deliver(alert, timeout_s)
            if attempts > 1:
                logger.info("alert sink %s: delivered on attempt %d", sink.name, attempts)
            return "sent", attempts, None
        except DeliveryError as exc:
            error, permanent, retry_after_s = str(exc), exc.permanent, exc.retry_after_s
        except Exception as exc:  # a bug or an odd library error must not lose the alert
            logger.exception("alert sink %s: unexpected error", sink.name)
            error, permanent = f"{type(exc).__name__}: {exc}", False
        logger.warning(
            "alert sink %s (%s): attempt %d of %d failed: %s",
            sink.name,
            sink.describe(),
            attempts,
            max_attempts,
            error,
        )
        if permanent:
            return "rejected", attempts, error
        if attempts >= max_attempts:
            return "pending", attempts, error
        pause_s = max(wait_s * random.uniform(0.5, 1.0), retry_after_s or 0.0)
        if time.monotonic() + pause_s >= deadline:
            return "pending", attempts, error
        time.sleep(pause_s)
        wait_s *= 2
