"""Sending the nightly verdict to the alert sinks, with retries and an outbox.

The monitor stores the run in its history first and then calls
:func:`send_alerts`, so that no sink, however slow or broken, can block or
lose the history write. :func:`send_alerts`:

1. delivers what earlier runs left in the outbox (:func:`deliver_pending`);
2. makes the alert (:func:`~imu_square.monitor.alerts.alert.make_alert`) and,
   for each sink whose ``states`` hold tonight's state, writes it to the
   outbox before the first try (a process killed mid-delivery loses nothing);
3. tries the sinks in parallel, each up to ``attempts`` times with
   exponential back-off and jitter, and never past ``max_total_s``
   (socket timeouts are cut to the time left);
4. removes each delivered entry; keeps one that failed for now (the next call
   retries it); moves one that a sink refused as a configuration error (HTTP
   4xx, refused login, bad certificate, missing secret) to ``rejected/``,
   where it stays, logged, until :func:`deliver_pending` is called with
   ``include_rejected=True`` after the monitor file is fixed.

Each of steps 1 and 3 takes at most ``max_total_s`` (10 s by default), so one
call takes at most twice that. Delivery is at least once: a receiver that
must not see an alert twice dedupes on its ``alert_id``.

Nothing here runs a program or a shell; every configured string is used as
data (a URL, a header value, an address, a file path).
"""

import random
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path

from imu_square.errors import MonitorError
from imu_square.log import logger
from imu_square.monitor.alerts import outbox
from imu_square.monitor.alerts.alert import DeliveryError, make_alert


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
        ``"pending"`` (failed for now, kept in the outbox and retried at the
        next call); ``"rejected"`` (a configuration error, kept in the
        outbox's ``rejected/`` and not retried); ``"failed"`` (not delivered
        and the outbox could not be written either: the alert is only in the
        log).
    attempts : int
        Tries in this call.
    error : str or None
        The last failure.
    outbox_path : str or None
        Where the alert waits, for ``pending`` and ``rejected``.
    """

    sink: str
    alert_id: str
    state: str
    status: str
    attempts: int = 0
    error: str | None = None
    outbox_path: str | None = None

    def as_dict(self):
        """The outcome as a JSON-ready dict."""
        return asdict(self)


@dataclass(frozen=True)
class AlertReport:
    """The result of :func:`send_alerts`.

    Attributes
    ----------
    alert : Alert
        Tonight's alert.
    outcomes : tuple of SinkOutcome
        Tonight's alert at each sink, in the configuration's order.
    backlog : tuple of SinkOutcome
        Earlier alerts from the outbox tried in this call.
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
            "alert_id": self.alert.alert_id,
            "delivered": self.delivered,
            "outcomes": [o.as_dict() for o in self.outcomes],
            "backlog": [o.as_dict() for o in self.backlog],
        }


def send_alerts(config, record, *, machine_id, state, verdict, outbox_dir=None, now=None):
    """Send tonight's verdict to every sink that takes its state (module docstring).

    Never raises for a sink's failure: failures are logged and reported in the
    outcomes, and the alert is kept in the outbox.

    Parameters
    ----------
    config : AlertsConfig
        The ``[alerts]`` section.
    record : dict
        The run's record, JSON-ready (see
        :func:`~imu_square.monitor.alerts.alert.json_ready`).
    machine_id : str
        The machine's id.
    state : str
        One of :data:`~imu_square.monitor.alerts.alert.STATES`.
    verdict : str
        The one-line verdict.
    outbox_dir : str or Path, optional
        The outbox folder; ``config.outbox`` by default. One of them must be given.
    now : datetime, optional
        The alert's time (aware); the current time by default.

    Returns
    -------
    AlertReport
    """
    folder = _outbox(config, outbox_dir)
    alert = make_alert(record, machine_id=machine_id, state=state, verdict=verdict, now=now)
    backlog = _safely("the outbox", deliver_pending, config, folder) or ()
    selected = [s for s in config.sinks if state in s.states]
    deadline = time.monotonic() + config.retry.max_total_s

    def send(sink):
        done = _safely(sink.name, _send_new, sink, alert, config.retry, deadline, folder)
        return done or SinkOutcome(sink.name, alert.alert_id, state, "failed", error="see the log")

    with ThreadPoolExecutor(max_workers=max(1, len(selected))) as pool:
        done = dict(zip([s.name for s in selected], pool.map(send, selected), strict=True))
    outcomes = tuple(
        done.get(s.name) or SinkOutcome(s.name, alert.alert_id, state, "skipped")
        for s in config.sinks
    )
    return AlertReport(alert=alert, outcomes=outcomes, backlog=backlog)


def deliver_pending(config, outbox_dir=None, *, include_rejected=False):
    """Try again what earlier calls left in the outbox, oldest first.

    Each entry gets one try, sinks in parallel, within ``max_total_s``. A sink
    that fails for now is not tried again in this call for its later
    entries (they stay pending, ``attempts`` 0): it is evidently down. An
    entry whose sink is no longer in the monitor file, or whose file cannot
    be read, moves to ``rejected/`` with an error in the log. Entries another
    process is delivering right now are left to it.

    Parameters
    ----------
    config : AlertsConfig
        The ``[alerts]`` section.
    outbox_dir : str or Path, optional
        The outbox folder; ``config.outbox`` by default.
    include_rejected : bool
        First move the rejected entries back, after the monitor file is fixed.

    Returns
    -------
    tuple of SinkOutcome
        One per entry tried or left pending, sink by sink, oldest first.

    Raises
    ------
    MonitorError
        If the outbox folder cannot be read (a sink's failure never raises).
    """
    folder = _outbox(config, outbox_dir)
    by_sink = {}
    try:
        if include_rejected:
            moved = outbox.requeue_rejected(folder)
            if moved:
                logger.info("alert outbox %s: %d rejected alert(s) queued again", folder, moved)
        for path in outbox.pending_paths(folder):
            by_sink.setdefault(outbox.sink_of(path), []).append(path)
    except OSError as exc:
        raise MonitorError(f"{folder}: cannot read the alert outbox: {exc}") from None
    if not by_sink:
        return ()
    deadline = time.monotonic() + config.retry.max_total_s
    results = []
    for name in [n for n in by_sink if config.sink(n) is None]:
        results += [_safely(path.name, _orphan, path, name) for path in by_sink.pop(name)]
    with ThreadPoolExecutor(max_workers=max(1, len(by_sink))) as pool:
        jobs = [
            pool.submit(_safely, name, _send_backlog, config.sink(name), paths, config.retry,
                        deadline)
            for name, paths in by_sink.items()
        ]  # fmt: skip
        for job in jobs:
            results += job.result() or []
    return tuple(r for r in results if r is not None)


def _safely(what, function, *args):
    """``function(*args)``, or None after logging an unexpected error: delivery never raises."""
    try:
        return function(*args)
    except Exception:
        logger.exception("alert delivery: unexpected error in %s", what)
        return None


def _outbox(config, outbox_dir):
    folder = outbox_dir if outbox_dir is not None else config.outbox
    if folder is None:
        raise ValueError("no outbox folder: pass outbox_dir or set [alerts] outbox")
    return Path(folder)


def _send_new(sink, alert, retry, deadline, folder):
    """Deliver tonight's alert to one sink; never raises."""
    if sink.kind == "log":  # logging cannot fail in a way a retry would fix
        sink.deliver(alert)
        return SinkOutcome(sink.name, alert.alert_id, alert.state, "sent", attempts=1)
    try:
        entry = outbox.create(folder, alert, sink.name)
    except OSError as exc:
        entry = None
        logger.error(
            "alert outbox %s cannot be written (%s): trying %s anyway", folder, exc, sink.name
        )
    status, attempts, error = _try(sink, alert, retry, deadline, retry.attempts)
    return _settle(sink, alert, entry, status, attempts, error)


def _send_backlog(sink, paths, retry, deadline):
    """Deliver one sink's pending entries, oldest first; stop at its first transient failure."""
    results = []
    down = None
    for path in paths:
        try:
            entry = outbox.claim(path)
        except ValueError as exc:
            target = outbox.reject_file(path)
            logger.error("%s; moved to %s", exc, target)
            continue
        if entry is None:  # another process is delivering it
            continue
        alert = entry.alert
        if down is not None:
            outbox.release(entry)
            results.append(
                SinkOutcome(
                    sink.name,
                    alert.alert_id,
                    alert.state,
                    "pending",
                    0,
                    f"not tried: {sink.name} failed on an earlier alert ({down})",
                    str(path),
                )
            )
            continue
        status, attempts, error = _try(sink, alert, retry, deadline, 1)
        results.append(_settle(sink, alert, entry, status, attempts, error))
        if status == "pending":
            down = error
    return results


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


def _settle(sink, alert, entry, status, attempts, error):
    """Record the result of a round in the outbox and make the outcome; never raises."""
    path = None if entry is None else entry.path
    try:
        if entry is None:
            if status != "sent":
                # The outbox cannot be written: the log is the last place the alert survives.
                logger.error(
                    "alert for %s not delivered and not kept: %s",
                    sink.name,
                    alert.to_json().decode("utf-8"),
                )
                status = "failed"
        elif status == "sent":
            outbox.remove(entry)
            path = None
        elif status == "pending":
            outbox.update(entry, attempts, error)
            logger.warning(
                "alert sink %s: alert kept in %s, retried at the next run", sink.name, entry.path
            )
        else:
            path = outbox.reject(entry, attempts, error)
            logger.error(
                "alert sink %s refused the alert (a configuration error, not retried): "
                "%s; kept in %s until the monitor file is fixed and the outbox "
                "re-queued",
                sink.name,
                error,
                path,
            )
    except OSError as exc:
        logger.error(
            "alert outbox: cannot record the %s alert for %s in %s: %s",
            status,
            sink.name,
            path,
            exc,
        )
    finally:
        if entry is not None:
            outbox.release(entry)
    return SinkOutcome(
        sink.name,
        alert.alert_id,
        alert.state,
        status,
        attempts,
        error,
        None if path is None else str(path),
    )


def _orphan(path, name):
    """Move an entry whose sink left the monitor file to ``rejected/``."""
    try:
        entry = outbox.claim(path)
    except ValueError as exc:
        logger.error("%s; moved to %s", exc, outbox.reject_file(path))
        return None
    if entry is None:
        return None
    error = f"the sink {name!r} is no longer in the monitor file"
    try:
        target = outbox.reject(entry, 0, error)
    finally:
        outbox.release(entry)
    logger.error("alert outbox: %s; %s moved to %s", error, path.name, target)
    return SinkOutcome(
        name, entry.alert.alert_id, entry.alert.state, "rejected", 0, error, str(target)
    )
