"""Alert sinks end to end: the log, JSON files, the outbox's corner cases, and no shell anywhere."""

import datetime as dt
import json
import logging
import math
import re
import stat
import urllib.parse
from pathlib import Path

import pytest
from alert_servers import Hook, Mailbox, free_port

import imu_square.monitor
from imu_square.errors import ImuSquareError
from imu_square.monitor.alerts.alert import make_alert, one_line
from imu_square.monitor.alerts.config import alerts_from_mapping
from imu_square.monitor.alerts.json_file import JsonFileSink
from imu_square.monitor.alerts.send import deliver_alerts, queue_alert
from imu_square.monitor.history.store import open_history

# aiosmtpd counts only STARTTLS as TLS and warns when AUTH is allowed without it.
pytestmark = pytest.mark.filterwarnings("ignore:Requiring AUTH while not requiring TLS")

RECORD = {"change_urad": 14.2, "u_change_urad": 3.1, "warnings": ["slow feed"]}


@pytest.fixture
def history(tmp_path_factory):
    with open_history(tmp_path_factory.mktemp("history") / "history.db") as h:
        yield h


def send(
    config, history, state="alarm", verdict="changed", machine_id="mill-3", record=RECORD, now=None
):
    """A night's alert kept in the outbox, then delivered with what is pending."""
    alert = queue_alert(
        config, history, record, machine_id=machine_id, state=state, verdict=verdict, now=now
    )
    return deliver_alerts(config, history, machine_id, alert)


def by_sink(report):
    return {o.sink: o for o in report.outcomes}


def test_the_log_line_has_a_level_per_state_and_cannot_be_split(history, caplog):
    config = alerts_from_mapping(None)
    caplog.set_level(logging.INFO, logger="imu_square")
    for state, level in [("ok", "INFO"), ("stale_baseline", "WARNING"), ("alarm", "ERROR")]:
        caplog.clear()
        send(
            config,
            history,
            state=state,
            verdict="line one\nFAKE: second line",
            machine_id="m\r\n1",
        )
        (record,) = [r for r in caplog.records if r.getMessage().startswith("alert:")]
        assert record.levelname == level
        assert record.getMessage() == f"alert: machine 'm 1' {state}: line one FAKE: second line"
    # Only the log sink: nothing is kept in the outbox.
    assert history.outbox("m\r\n1") == [] and history.outbox("m\r\n1", "delivered") == []


def test_the_latest_json_file_holds_the_newest_alert_whatever_the_delivery_order(tmp_path, history):
    path = tmp_path / "latest.json"
    config = alerts_from_mapping({"json_file": {"path": str(path)}})
    report = send(config, history)
    assert by_sink(report)["json_file"].status == "sent"
    assert json.loads(path.read_text()) == report.alert.as_dict()
    # A dashboard running as another user can read it, and no temporary file is left.
    assert stat.S_IMODE(path.stat().st_mode) == 0o644
    assert sorted(p.name for p in tmp_path.iterdir()) == ["latest.json"]
    sink = config.sink("json_file")
    t = dt.datetime.now(dt.UTC) + dt.timedelta(days=1)
    newer = make_alert(RECORD, machine_id="m", state="ok", verdict="newer", now=t)
    older = make_alert(
        RECORD, machine_id="m", state="alarm", verdict="older", now=t - dt.timedelta(days=1)
    )
    sink.deliver(newer)
    sink.deliver(older)  # late, from the outbox
    assert json.loads(path.read_text())["verdict"] == "newer"


def test_the_append_file_is_json_lines_with_each_alert_once(tmp_path, history):
    path = tmp_path / "alerts.jsonl"
    config = alerts_from_mapping(
        {"json_file": {"path": str(path), "mode": "append", "states": ["ok", "alarm"]}}
    )
    reports = [send(config, history, state=s) for s in ("ok", "alarm", "warning", "ok")]
    assert [by_sink(r)["json_file"].status for r in reports] == ["sent", "sent", "skipped", "sent"]
    lines = path.read_text().splitlines()
    assert [json.loads(line)["alert_id"] for line in lines] == [
        reports[i].alert.alert_id for i in (0, 1, 3)
    ]
    config.sink("json_file").deliver(reports[1].alert)  # delivered twice: still one line
    assert len(path.read_text().splitlines()) == 3


def test_a_json_file_whose_folder_is_missing_waits_in_the_outbox_until_it_exists(tmp_path, history):
    folder = tmp_path / "not-mounted"
    config = alerts_from_mapping(
        {"json_file": {"path": str(folder / "latest.json")}, "attempts": 2, "backoff_s": 0.01}
    )
    first = send(config, history)
    result = by_sink(first)["json_file"]
    assert (result.status, result.attempts) == ("pending", 2)
    assert "cannot write" in result.error and "No such file or directory" in result.error
    folder.mkdir()
    second = send(config, history, state="warning")
    assert [o.status for o in second.backlog] == ["sent"]
    assert json.loads((folder / "latest.json").read_text())["alert_id"] == second.alert.alert_id


def test_non_finite_numbers_become_null_and_the_report_is_json(tmp_path, history):
    path = tmp_path / "a.json"
    config = alerts_from_mapping({"json_file": {"path": str(path)}})
    record = {
        "change_urad": math.nan,
        "u_change_urad": math.inf,
        "n": [1.5, -math.inf],
        "p": Path("/x"),
    }
    report = send(config, history, state="invalid", record=record)
    assert json.loads(path.read_text())["record"] == {
        "change_urad": None, "u_change_urad": None, "n": [1.5, None], "p": "/x",
    }  # fmt: skip
    as_json = json.loads(json.dumps(report.as_dict(), allow_nan=False))
    assert as_json["delivered"] is True
    assert [o["status"] for o in as_json["outcomes"]] == ["sent", "sent"]


def test_a_bad_state_or_record_is_refused_before_anything_is_sent(tmp_path, history):
    config = alerts_from_mapping({"json_file": {"path": str(tmp_path / "a.json")}})
    with pytest.raises(ImuSquareError, match=r"state must be one of .*got 'alarming'"):
        send(config, history, state="alarming")
    with pytest.raises(TypeError, match=r"record.when: cannot be sent as JSON: object"):
        send(config, history, record={"when": object()})
    assert not (tmp_path / "a.json").exists()
    assert history.outbox("mill-3") == []


def test_the_alerts_are_kept_with_the_night_or_not_at_all(history):
    # Written in the night's transaction: a night that fails to be stored leaves no alert,
    # and nothing is sent before the commit.
    with Hook() as hook:
        config = alerts_from_mapping({"webhook": {"url": hook.url}})
        with pytest.raises(RuntimeError, match="the night could not be stored"):
            with history.transaction():
                queue_alert(
                    config, history, RECORD, machine_id="mill-3", state="alarm", verdict="v"
                )
                assert len(history.outbox("mill-3")) == 1 and hook.requests == []
                raise RuntimeError("the night could not be stored")
        assert history.outbox("mill-3") == []
        with history.transaction():
            alert = queue_alert(
                config, history, RECORD, machine_id="mill-3", state="alarm", verdict="v"
            )
        assert [r.alert_id for r in history.outbox("mill-3")] == [alert.alert_id]
        assert hook.requests == []
        report = deliver_alerts(config, history, "mill-3", alert)
    assert by_sink(report)["webhook"].status == "sent" and len(hook.requests) == 1
    (row,) = history.outbox("mill-3", "delivered")
    assert (row.alert_id, row.sink, row.attempts) == (alert.alert_id, "webhook", 1)


def test_a_sink_that_fails_unexpectedly_keeps_its_alert_and_the_others_still_get_theirs(
    tmp_path, history, monkeypatch, caplog
):
    def broken(self, alert, timeout_s=None):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(JsonFileSink, "deliver", broken)
    with Hook() as hook:
        config = alerts_from_mapping(
            {"json_file": {"path": str(tmp_path / "a.json")}, "webhook": {"url": hook.url},
             "attempts": 1}
        )  # fmt: skip
        report = send(config, history)
    assert [(o.sink, o.status) for o in report.outcomes] == [
        ("log", "sent"), ("json_file", "pending"), ("webhook", "sent"),
    ]  # fmt: skip
    assert by_sink(report)["json_file"].error == "ZeroDivisionError: a bug"
    assert [r.sink for r in history.outbox("mill-3")] == ["json_file"]
    assert any("unexpected error" in r.getMessage() for r in caplog.records)


def test_alerts_of_a_removed_sink_are_rejected_and_kept(history):
    port = free_port()
    config = alerts_from_mapping(
        {"webhook": [{"name": "old", "url": f"http://127.0.0.1:{port}/"},
                     {"name": "kept", "url": f"http://127.0.0.1:{port}/"}], "attempts": 1}
    )  # fmt: skip
    report = send(config, history)
    assert [o.status for o in report.outcomes] == ["sent", "pending", "pending"]
    with Hook(port=port) as hook:
        later = alerts_from_mapping({"webhook": {"name": "kept", "url": hook.url}})
        results = deliver_alerts(later, history, "mill-3").backlog
    assert sorted((o.sink, o.status) for o in results) == [("kept", "sent"), ("old", "rejected")]
    assert "no longer in the monitor file" in next(o.error for o in results if o.sink == "old")
    assert len(hook.requests) == 1
    (rejected,) = history.outbox("mill-3", "rejected")
    assert rejected.sink == "old" and "no longer in the monitor file" in rejected.last_error
    assert rejected.id == next(o.outbox_id for o in results if o.sink == "old")
    assert history.outbox("mill-3") == []
    # Kept, not retried: the next round leaves it alone.
    assert deliver_alerts(later, history, "mill-3").backlog == ()


def test_the_monitor_package_never_starts_a_process():
    # Configured strings are data only: no code path hands one to a shell or a program.
    # The one exception is the PostgreSQL backup, which runs pg_dump from an argument
    # list (never a shell): checked separately below.
    forbidden = re.compile(
        r"\bsubprocess\b|os\.system|os\.popen|os\.exec|os\.spawn|shell\s*=|\beval\(|\bexec\("
    )
    folder = Path(imu_square.monitor.__file__).parent
    sources = {p.relative_to(folder).as_posix(): p.read_text() for p in folder.rglob("*.py")}
    assert "alerts/send.py" in sources and "alerts/webhook.py" in sources
    pg = sources.pop("history/postgres.py")
    assert {
        name: forbidden.findall(text) for name, text in sources.items() if forbidden.search(text)
    } == {}
    assert re.findall(r"subprocess\.\w+\(", pg) == ["subprocess.run("]
    assert not re.search(r"shell\s*=|os\.system|os\.popen|\beval\(|\bexec\(", pg)


# Shell metacharacters, quotes, non-ASCII; the markers say whether a shell ever ran them.
SHELL = "$(touch pwned) `touch pwned`; touch pwned | touch pwned && rm -rf victim"
QUOTES = "'single' \"double\" \\back\\slash %s {} * ?"
LATIN1 = f"{SHELL} {QUOTES} ü µm/m"  # what an HTTP header can carry
META = f"{LATIN1} € 測"
META_LINES = f"{META}\nsecond line\r\nBcc: thief@localhost"


def test_shell_metacharacters_in_every_field_of_every_sink_arrive_verbatim_and_run_nothing(
    tmp_path, history, monkeypatch, caplog
):
    monkeypatch.chdir(tmp_path)  # where a shell running "touch pwned" would leave its mark
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "keep").write_text("still here")
    ascii_meta = f"{SHELL} {QUOTES}"
    monkeypatch.setenv("HOOK_TOKEN", LATIN1)
    monkeypatch.setenv("SMTP_PASSWORD", ascii_meta)
    secret = tmp_path / f"{SHELL} password"
    secret.write_text(ascii_meta + "\n")
    latest = f"{SHELL} {QUOTES} ü € latest.json"
    every = f"{SHELL} ü every.jsonl"
    hook_path = (
        "/hook/$(touch%20pwned)/`touch%20pwned`;touch%20pwned|touch%20pwned&&rm%20-rf%20victim/ü"
    )
    hook_query = "q=$(touch%20pwned)&r='\"`id`\"'"
    sender = f'"{ascii_meta.replace(chr(92), "").replace(chr(34), "")}" <noreply@localhost>'
    recipient = '"$(touch pwned);`touch pwned`|touch pwned&&rm -rf victim"@localhost'
    states = ["alarm"]
    with Hook() as hook, Mailbox(login=(ascii_meta.encode(), ascii_meta.encode())) as box:
        table = {
            "states": states,
            "log": {"states": states},
            "json_file": [{"path": latest}, {"path": every, "mode": "append"}],
            "webhook": [
                {"url": f"{hook.url}{hook_path}?{hook_query}", "headers": {"X-Meta": LATIN1},
                 "token_env": "HOOK_TOKEN", "token_prefix": f"{SHELL} "},
            ],
            "email": [
                {"host": "127.0.0.1", "port": box.port, "security": "none", "sender": sender,
                 "to": [recipient], "username": ascii_meta, "password_env": "SMTP_PASSWORD"},
                {"host": "127.0.0.1", "port": box.port, "security": "none", "sender": sender,
                 "to": [recipient], "username": ascii_meta, "password_file": secret.name},
            ],
        }  # fmt: skip
        config = alerts_from_mapping(table, "monitor.toml", base_dir=tmp_path)
        record = {"machine_id": META_LINES, "recording": f"/data/{META}.mcap", META: [META_LINES]}
        report = send(config, history, machine_id=META_LINES, verdict=META_LINES, record=record)
    assert [(o.sink, o.status) for o in report.outcomes] == [
        ("log", "sent"), ("json_file-1", "sent"), ("json_file-2", "sent"), ("webhook", "sent"),
        ("email-1", "sent"), ("email-2", "sent"),
    ]  # fmt: skip
    expected = report.alert.as_dict()
    assert expected["machine_id"] == META_LINES and expected["verdict"] == META_LINES
    assert expected["record"] == record
    # JSON files: at exactly the configured names, holding the alert unchanged.
    assert json.loads((tmp_path / latest).read_text()) == expected
    assert json.loads((tmp_path / every).read_text()) == expected
    # Webhook: URL, headers, token and body as configured and given.
    (request,) = hook.requests
    path, _, query = request["path"].partition("?")
    assert urllib.parse.unquote(path) == urllib.parse.unquote(hook_path)
    assert query == hook_query
    assert request["headers"]["X-Meta"] == LATIN1
    assert request["headers"]["Authorization"] == f"{SHELL} {LATIN1}"
    assert json.loads(request["body"]) == expected
    # E-mail: envelope, login, headers (one line each), body.
    assert box.logins == [(ascii_meta.encode(), ascii_meta.encode())] * 2
    for mail in box.messages:
        assert mail["rcpt_tos"] == [recipient] and mail["mail_from"] == "noreply@localhost"
        msg = mail["message"]
        assert msg["Subject"] == f"[imu-square] {one_line(META_LINES)}: alarm"
        assert msg["From"].addresses[0].display_name == sender.split('"')[1]
        assert msg["To"].addresses[0].addr_spec == recipient
        assert msg["Bcc"] is None
        assert json.loads(next(msg.iter_attachments()).get_content()) == expected
    # The log: one line.
    line = f"alert: machine {one_line(META_LINES)!r} alarm: {one_line(META_LINES)}"
    assert any(r.getMessage() == line for r in caplog.records)
    # And nothing ran.
    assert not (tmp_path / "pwned").exists() and not Path("pwned").exists()
    assert (victim / "keep").read_text() == "still here"


def test_the_user_guide_lists_the_fields_every_sink_sends():
    guide = Path(__file__).resolve().parents[1] / "docs" / "user-guide" / "alerts-metrics.md"
    said = " ".join(guide.read_text(encoding="utf-8").split())
    listed = re.search(r"Every sink sends the same JSON object: (.*?)\. ", said).group(1)
    sent = make_alert({"run_id": 1}, machine_id="mill-3", state="ok", verdict="v").as_dict()
    assert set(re.findall(r"`([a-z_]+)`", listed)) == set(sent)
    assert f"`schema` (`{sent['schema']}`)" in listed
