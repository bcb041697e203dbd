"""The webhook sink against a real HTTP server on localhost: retries, outbox, timeouts, TLS."""

import json
import os
import signal
import subprocess
import sys
import threading
import time
from datetime import UTC, datetime, timedelta

import pg_server
import pytest
from alert_servers import Hook, SilentServer, free_port, self_signed_cert, server_tls_context

from imu_square.monitor.alerts.config import alerts_from_mapping
from imu_square.monitor.alerts.send import deliver_alerts, queue_alert
from imu_square.monitor.history.store import open_history

RECORD = {
    "machine_id": "mill-3",
    "state": "alarm",
    "change_urad": 14.2,
    "u_change_urad": 3.1,
    "recorded_at": "2026-10-03T02:10:00+00:00",
    "recording": "/var/lib/imu-square/mill-3/nightly-20261003.mcap",
    "warnings": [],
}
VERDICT = "changed by +14 ± 3 µm/m: check the machine"


def alerts(webhooks, attempts=3, backoff_s=0.05, max_total_s=5.0, **extra):
    table = {"attempts": attempts, "backoff_s": backoff_s, "max_total_s": max_total_s, **extra}
    table["webhook"] = webhooks if isinstance(webhooks, list) else [webhooks]
    return alerts_from_mapping(table, "monitor.toml")


@pytest.fixture
def history(tmp_path):
    with open_history(tmp_path / "history.db") as h:
        yield h


@pytest.fixture(params=["sqlite", "postgresql"])
def location(request, tmp_path):
    return pg_server.location_for(request.param, tmp_path)


def send(config, history, state="alarm", verdict=VERDICT, machine_id="mill-3", record=RECORD):
    """A night's alert kept in the outbox, then delivered with what is pending."""
    alert = queue_alert(
        config, history, record, machine_id=machine_id, state=state, verdict=verdict
    )
    return deliver_alerts(config, history, machine_id, alert)


def deliver_pending(config, history, **options):
    return deliver_alerts(config, history, "mill-3", **options).backlog


def outcome(report, sink="webhook"):
    return next(o for o in report.outcomes if o.sink == sink)


def pending(history):
    return [r.alert_id for r in history.outbox("mill-3")]


def test_the_alert_arrives_as_json_with_its_headers_and_token(tmp_path, history, monkeypatch):
    monkeypatch.setenv("HOOK_TOKEN", "s3cret")
    with Hook() as hook:
        config = alerts(
            {
                "url": f"{hook.url}/imu?shop=2",
                "headers": {"X-Shop": "hall 2"},
                "token_env": "HOOK_TOKEN",
            }
        )
        report = send(config, history)
    assert outcome(report).status == "sent" and outcome(report).attempts == 1
    assert outcome(report, "log").status == "sent" and report.delivered
    (request,) = hook.requests
    assert request["path"] == "/imu?shop=2"
    body = json.loads(request["body"])
    assert body == report.alert.as_dict()
    assert body["record"] == RECORD and body["verdict"] == VERDICT and body["state"] == "alarm"
    headers = request["headers"]
    assert headers["Content-Type"] == "application/json; charset=utf-8"
    assert headers["Idempotency-Key"] == report.alert.alert_id
    assert headers["X-Shop"] == "hall 2"
    assert headers["Authorization"] == "Bearer s3cret"
    assert headers["User-Agent"].startswith("imu-square/")
    # Delivered: nothing left in the outbox, and the token is in no file (the history neither).
    assert pending(history) == []
    assert not any(b"s3cret" in p.read_bytes() for p in tmp_path.rglob("*") if p.is_file())


def test_a_state_the_sink_does_not_take_is_skipped(history):
    with Hook() as hook:
        report = send(alerts({"url": hook.url}), history, state="ok", verdict="unchanged")
    assert outcome(report).status == "skipped" and hook.requests == []
    assert outcome(report, "log").status == "sent"  # the log takes every state


def test_two_503_then_success_is_retried_with_growing_back_off(history):
    with Hook(replies=[503, 503]) as hook:
        report = send(alerts({"url": hook.url}, attempts=4, backoff_s=0.2), history)
    result = outcome(report)
    assert (result.status, result.attempts, result.error) == ("sent", 3, None)
    assert len(hook.requests) == 3
    # The same alert each time, so a receiver can drop duplicates.
    assert len({r["headers"]["Idempotency-Key"] for r in hook.requests}) == 1
    t = [r["t"] for r in hook.requests]
    # Waits are 50-100 % of 0.2 s, then of 0.4 s.
    assert 0.1 <= t[1] - t[0] <= 0.3
    assert 0.2 <= t[2] - t[1] <= 0.5
    assert pending(history) == []


def test_retry_after_is_honoured(history):
    with Hook(replies=[(429, {"Retry-After": "1"})]) as hook:
        report = send(alerts({"url": hook.url}, backoff_s=0.01), history)
    assert outcome(report).status == "sent" and outcome(report).attempts == 2
    assert hook.requests[1]["t"] - hook.requests[0]["t"] >= 1.0


def test_a_server_that_is_down_keeps_the_alert_and_the_next_run_delivers_it(location):
    port = free_port()
    config = alerts({"url": f"http://127.0.0.1:{port}/hook"}, attempts=2)
    with open_history(location) as history:
        first = send(config, history)
        result = outcome(first)
        assert result.status == "pending" and result.attempts == 2
        assert "cannot reach the server" in result.error and "refused" in result.error.lower()
        assert not first.delivered
        (kept,) = history.outbox("mill-3")
        assert result.outbox_id == kept.id
        assert kept.alert == first.alert.as_dict() and kept.attempts == 2
        assert kept.sink == "webhook" and "refused" in kept.last_error.lower()

    with open_history(location) as history, Hook(port=port) as hook:  # the next night
        second = send(config, history, state="warning", verdict="drifting")
        assert pending(history) == []
    (backlog,) = second.backlog
    assert (backlog.alert_id, backlog.status) == (first.alert.alert_id, "sent")
    assert outcome(second).status == "sent"
    # Oldest first: last night's alert, then tonight's.
    assert [b["alert_id"] for b in hook.bodies()] == [first.alert.alert_id, second.alert.alert_id]
    assert hook.bodies()[0] == first.alert.as_dict()


def test_deliver_pending_alone_empties_the_outbox_and_a_down_sink_is_tried_once(history):
    port = free_port()
    config = alerts({"url": f"http://127.0.0.1:{port}/"}, attempts=1)
    ids = [send(config, history).alert.alert_id for _ in range(3)]
    assert len(pending(history)) == 3
    # Still down: the first entry is tried, the two others wait without a try.
    still = deliver_pending(config, history)
    assert [(o.alert_id, o.status, o.attempts) for o in still] == [
        (ids[0], "pending", 1), (ids[1], "pending", 0), (ids[2], "pending", 0),
    ]  # fmt: skip
    kept = history.outbox("mill-3")[0]
    # Its own run, the two later runs (each tries the oldest entry first), and now.
    assert kept.attempts == 4
    with Hook(port=port) as hook:
        done = deliver_pending(config, history)
    assert [o.status for o in done] == ["sent"] * 3
    assert [b["alert_id"] for b in hook.bodies()] == ids
    assert pending(history) == [] and deliver_pending(config, history) == ()


def test_a_hanging_server_costs_the_timeout_per_attempt_and_never_more_than_the_cap(
    tmp_path, history
):
    with SilentServer() as silent, open_history(tmp_path / "b.db") as other:
        url = f"http://127.0.0.1:{silent.port}/"
        start = time.monotonic()
        report = send(alerts({"url": url, "timeout_s": 0.3}, attempts=2, backoff_s=0.0), history)
        elapsed = time.monotonic() - start
        assert outcome(report).status == "pending" and outcome(report).attempts == 2
        assert "timed out" in outcome(report).error
        assert 0.6 <= elapsed < 1.2
        # Ten attempts of 0.4 s would take 4 s; the cap of 1 s stops them.
        start = time.monotonic()
        capped = alerts({"url": url, "timeout_s": 0.4}, attempts=10, backoff_s=0.0, max_total_s=1.0)
        report = send(capped, other)
        elapsed = time.monotonic() - start
        assert outcome(report).status == "pending" and outcome(report).attempts == 3
        assert 0.95 <= elapsed < 1.5
        assert len(pending(other)) == 1


def test_sinks_are_tried_one_after_the_other_each_within_its_own_cap(history):
    # No thread pool: a hanging sink costs its own cap, then the next sink gets its alert.
    with SilentServer() as silent, Hook() as hook:
        hooks = [
            {"url": f"http://127.0.0.1:{silent.port}/", "timeout_s": 0.5},
            {"url": hook.url, "timeout_s": 0.5},
        ]
        start = time.monotonic()
        report = send(alerts(hooks, attempts=2, backoff_s=0.0, max_total_s=0.8), history)
        elapsed = time.monotonic() - start
    assert [o.status for o in report.outcomes] == ["sent", "pending", "sent"]
    assert len(hook.requests) == 1
    assert 0.75 <= elapsed < 1.5  # the silent sink's 0.8 s cap, then the other at once


def test_a_4xx_is_a_configuration_error_kept_aside_until_requeued(location):
    with (
        Hook(replies=[(401, {"Content-Type": "text/plain"})]) as hook,
        open_history(location) as history,
    ):
        config = alerts({"url": hook.url}, attempts=4)
        first = send(config, history)
        result = outcome(first)
        assert (result.status, result.attempts) == ("rejected", 1)  # not retried
        assert "HTTP 401" in result.error and "configuration error" in result.error
        (rejected,) = history.outbox("mill-3", "rejected")  # kept, and visible
        assert result.outbox_id == rejected.id and "HTTP 401" in rejected.last_error
        assert pending(history) == []
        # The next run does not retry it; tonight's alert goes through.
        second = send(config, history)
        assert second.backlog == () and outcome(second).status == "sent"
        assert len(hook.requests) == 2
        # After the configuration is fixed, the rejected alert is queued again on request.
        again = deliver_pending(config, history, include_rejected=True)
        assert history.outbox("mill-3", "rejected") == [] and pending(history) == []
    assert [(o.alert_id, o.status) for o in again] == [(first.alert.alert_id, "sent")]
    assert hook.bodies()[2] == first.alert.as_dict()


def test_a_redirect_is_refused_not_followed(history):
    with Hook() as target, Hook(replies=[(302, {"Location": f"{target.url}/new"})]) as hook:
        report = send(alerts({"url": hook.url}), history)
    assert outcome(report).status == "rejected"
    assert "redirects are not followed" in outcome(report).error
    assert f"{target.url}/new" in outcome(report).error
    assert target.requests == []


def test_https_verifies_the_certificate_against_ca_file(tmp_path, history):
    cert, key = self_signed_cert(tmp_path)
    with Hook(tls=server_tls_context(cert, key)) as hook:
        trusted = send(alerts({"url": hook.url, "ca_file": str(cert)}), history)
        untrusted = send(alerts({"url": hook.url}), history)
    assert outcome(trusted).status == "sent"
    assert outcome(untrusted).status == "rejected"
    assert "certificate does not verify" in outcome(untrusted).error
    assert len(hook.requests) == 1


def test_url_and_token_come_from_the_environment_and_their_absence_is_a_configuration_error(
    history, monkeypatch
):
    with Hook() as hook:
        config = alerts({"url_env": "HOOK_URL", "token_env": "HOOK_TOKEN"})
        monkeypatch.delenv("HOOK_URL", raising=False)
        monkeypatch.setenv("HOOK_TOKEN", "t")
        missing_url = outcome(send(config, history))
        monkeypatch.setenv("HOOK_URL", f"{hook.url}/from-env")
        monkeypatch.delenv("HOOK_TOKEN")
        missing_token = outcome(send(config, history))
        monkeypatch.setenv("HOOK_TOKEN", "evil\r\nX-Injected: 1")
        injected = outcome(send(config, history))
        monkeypatch.setenv("HOOK_TOKEN", "good")
        monkeypatch.setenv("HOOK_URL", "http://hooks.example.com/in-clear")
        in_clear = outcome(send(config, history))
        monkeypatch.setenv("HOOK_URL", f"{hook.url}/from-env")
        sent = outcome(send(config, history))
    assert missing_url.status == "rejected" and "HOOK_URL (url_env) is not set" in missing_url.error
    assert (
        missing_token.status == "rejected"
        and "HOOK_TOKEN (token_env) is not set" in missing_token.error
    )
    assert injected.status == "rejected" and "without CR, LF" in injected.error
    assert in_clear.status == "rejected" and "would cross the network in clear" in in_clear.error
    assert sent.status == "sent"
    (request,) = hook.requests
    assert request["path"] == "/from-env" and request["headers"]["Authorization"] == "Bearer good"
    assert "X-Injected" not in request["headers"]


def test_two_jobs_emptying_one_outbox_at_once_send_each_alert_once(location):
    # Two threads, each with its own connection: two processes as far as the history knows.
    port = free_port()
    config = alerts({"url": f"http://127.0.0.1:{port}/"}, attempts=1)
    with open_history(location) as history:
        ids = {send(config, history).alert.alert_id for _ in range(12)}
    start = threading.Barrier(2)
    results = []

    def job():
        with open_history(location) as history:
            start.wait()
            results.append(deliver_pending(config, history))

    with Hook(port=port, delay_s=0.05) as hook:
        workers = [threading.Thread(target=job) for _ in range(2)]
        for w in workers:
            w.start()
        for w in workers:
            w.join()
    received = [b["alert_id"] for b in hook.bodies()]
    assert sorted(received) == sorted(ids)  # each exactly once
    # Both jobs delivered some: they really ran at the same time.
    assert sum(len(r) for r in results) == 12 and all(0 < len(r) < 12 for r in results)
    with open_history(location) as history:
        assert pending(history) == []


KILLED_SENDER = """
import sys
from imu_square.monitor.alerts.config import alerts_from_mapping
from imu_square.monitor.alerts.send import deliver_alerts, queue_alert
from imu_square.monitor.history.store import open_history
url, location = sys.argv[1:]
config = alerts_from_mapping({"webhook": {"url": url, "timeout_s": 60}, "max_total_s": 60})
with open_history(location) as history:
    alert = queue_alert(config, history, {"n": 1}, machine_id="mill-3", state="alarm", verdict="v")
    deliver_alerts(config, history, "mill-3", alert)
"""


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs POSIX kill -9")
def test_a_process_killed_while_sending_loses_nothing(location):
    hold = threading.Event()
    with Hook(hold=hold) as hanging:
        child = subprocess.Popen(
            [sys.executable, "-c", KILLED_SENDER, hanging.url, location],
            env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
        )
        try:
            assert hanging.arrived.wait(30), "the child never reached the webhook"
        finally:
            child.send_signal(signal.SIGKILL)
            child.wait()
    sent_id = json.loads(hanging.requests[0]["body"])["alert_id"]
    with Hook() as hook, open_history(location) as history:
        (kept,) = history.outbox("mill-3")  # committed before the first try, still claimed
        config = alerts({"url": hook.url})
        # The dead process's claim holds for now: nobody sends the alert twice at once ...
        assert deliver_pending(config, history) == () and hook.requests == []
        # ... and once it has run out (the next night), the alert goes.
        tomorrow = datetime.now(UTC) + timedelta(days=1)
        (result,) = deliver_pending(config, history, now=tomorrow)
        assert pending(history) == []
    assert (result.alert_id, result.status) == (sent_id, "sent")
    assert hook.bodies()[0]["alert_id"] == sent_id and sent_id == kept.alert_id
