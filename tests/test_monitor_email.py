"""The e-mail sink against a real SMTP server (aiosmtpd) on localhost: plain, STARTTLS, SMTPS."""

import json

import pytest
from alert_servers import Mailbox, SilentServer, free_port, self_signed_cert, server_tls_context

from imu_square.monitor.alerts.config import alerts_from_mapping
from imu_square.monitor.alerts.send import deliver_alerts, queue_alert
from imu_square.monitor.history.store import open_history

pytest.importorskip("aiosmtpd", reason="aiosmtpd is in the test extra: pip install -e .[test]")
# aiosmtpd counts only STARTTLS as TLS and warns when AUTH is allowed without it (SMTPS, plain).
pytestmark = pytest.mark.filterwarnings("ignore:Requiring AUTH while not requiring TLS")

RECORD = {"machine_id": "mill-3", "change_urad": 14.2, "u_change_urad": 3.1, "warnings": []}
VERDICT = "changed by +14 ± 3 µm/m: check the machine"


def alerts(port, attempts=3, backoff_s=0.05, max_total_s=5.0, **email):
    table = {
        "host": "127.0.0.1",
        "port": port,
        "security": "none",
        "sender": "imu-square <noreply@localhost>",
        "to": ["maint@localhost", "Quality <quality@localhost>"],
        "timeout_s": 2.0,
        **email,
    }
    return alerts_from_mapping(
        {"attempts": attempts, "backoff_s": backoff_s, "max_total_s": max_total_s, "email": table},
        "monitor.toml",
    )


def body_text(msg):
    """The text part, with the CRLF line ends of SMTP made LF."""
    return msg.get_body(("plain",)).get_content().replace("\r\n", "\n")


def send(config, history, state="alarm", machine_id="mill-3", verdict=VERDICT):
    """A night's alert kept in the outbox, then delivered with what is pending."""
    alert = queue_alert(
        config, history, RECORD, machine_id=machine_id, state=state, verdict=verdict
    )
    report = deliver_alerts(config, history, machine_id, alert)
    return report, report.outcomes[-1]


@pytest.fixture
def history(tmp_path):
    with open_history(tmp_path / "history.db") as h:
        yield h


@pytest.fixture(scope="module")
def cert(tmp_path_factory):
    return self_signed_cert(tmp_path_factory.mktemp("tls"))


def test_the_message_has_the_subject_headers_text_and_json_attachment(history):
    with Mailbox() as box:
        report, result = send(alerts(box.port), history)
    assert (result.sink, result.status, result.attempts) == ("email", "sent", 1)
    (mail,) = box.messages
    assert mail["mail_from"] == "noreply@localhost"
    assert mail["rcpt_tos"] == ["maint@localhost", "quality@localhost"]
    msg = mail["message"]
    assert msg["Subject"] == "[imu-square] mill-3: alarm"
    assert msg["From"] == "imu-square <noreply@localhost>"
    assert msg["To"] == "maint@localhost, Quality <quality@localhost>"
    assert msg["X-Imu-Square-State"] == "alarm"
    assert msg["X-Imu-Square-Machine-Id"] == "mill-3"
    assert msg["Message-ID"] == f"<{report.alert.alert_id}@imu-square.invalid>"
    assert msg["Date"].datetime == report.alert.created.replace(microsecond=0)
    text = body_text(msg)
    assert text.startswith(VERDICT + "\n\n")
    assert json.loads(text.split("\n\n", 1)[1]) == report.alert.as_dict()
    (attachment,) = list(msg.iter_attachments())
    assert attachment.get_content_type() == "application/json"
    assert attachment.get_filename() == "alert.json"
    assert json.loads(attachment.get_content()) == report.alert.as_dict()
    assert history.outbox("mill-3") == []


def test_starttls_with_login_verifies_the_server_and_sends_over_tls(history, cert, monkeypatch):
    certificate, key = cert
    monkeypatch.setenv("SMTP_PASSWORD", "pa55")
    with Mailbox(login=(b"imu", b"pa55"), tls=server_tls_context(certificate, key)) as box:
        config = alerts(
            box.port, security="starttls", username="imu", password_env="SMTP_PASSWORD",
            ca_file=str(certificate),
        )  # fmt: skip
        _, result = send(config, history)
        # The same server, not trusted: a configuration error, and no password sent.
        _, untrusted = send(alerts(box.port, security="starttls", username="imu",
                                   password_env="SMTP_PASSWORD"), history)  # fmt: skip
    assert result.status == "sent"
    assert box.logins == [(b"imu", b"pa55")]
    (mail,) = box.messages
    assert mail["tls"] is True
    assert untrusted.status == "rejected" and "certificate does not verify" in untrusted.error


def test_implicit_tls_with_the_password_from_a_file(tmp_path, history, cert):
    certificate, key = cert
    secret = tmp_path / "smtp-password"
    secret.write_text("from-file\n")
    with Mailbox(
        login=(b"imu", b"from-file"), implicit_tls=server_tls_context(certificate, key)
    ) as box:
        config = alerts(box.port, security="ssl", username="imu", password_file=str(secret),
                        ca_file=str(certificate))  # fmt: skip
        _, result = send(config, history)
    assert result.status == "sent" and box.messages[0]["tls"] is True
    assert box.logins == [(b"imu", b"from-file")]


def test_a_wrong_password_is_a_configuration_error(history, monkeypatch):
    monkeypatch.setenv("SMTP_PASSWORD", "wrong")
    with Mailbox(login=(b"imu", b"right")) as box:
        config = alerts(box.port, username="imu", password_env="SMTP_PASSWORD")
        _, result = send(config, history)
    assert (result.status, result.attempts) == ("rejected", 1)
    assert result.error.startswith("SMTP 535")
    assert box.messages == []
    assert [r.id for r in history.outbox("mill-3", "rejected")] == [result.outbox_id]


def test_a_missing_or_non_ascii_password_is_a_configuration_error(tmp_path, history, monkeypatch):
    monkeypatch.delenv("SMTP_PASSWORD", raising=False)
    with Mailbox(login=(b"imu", b"x")) as box:
        config = alerts(box.port, username="imu", password_env="SMTP_PASSWORD")
        _, missing = send(config, history)
        monkeypatch.setenv("SMTP_PASSWORD", "pässword")
        _, non_ascii = send(config, history)
        _, no_file = send(
            alerts(box.port, username="imu", password_file=str(tmp_path / "nope")), history
        )
    assert (
        missing.status == "rejected" and "SMTP_PASSWORD (password_env) is not set" in missing.error
    )
    assert non_ascii.status == "rejected" and "must be ASCII" in non_ascii.error
    assert no_file.status == "rejected" and "cannot read password_file" in no_file.error
    assert box.logins == []


def test_a_temporary_refusal_is_retried_and_a_permanent_one_is_not(history):
    with Mailbox(rcpt_replies=["451 4.3.0 try again later"] * 2) as box:
        _, retried = send(alerts(box.port, to=["maint@localhost"]), history)
    assert (retried.status, retried.attempts) == ("sent", 3)
    assert len(box.messages) == 1
    with Mailbox(rcpt_replies=["550 5.1.1 no such user"]) as box:
        _, refused = send(alerts(box.port, to=["nobody@localhost"]), history)
    assert (refused.status, refused.attempts) == ("rejected", 1)
    assert "550" in refused.error and "no such user" in refused.error
    # Two recipients, one refused: the mail goes to the other.
    with Mailbox(rcpt_replies=["550 5.1.1 no such user"]) as box:
        _, partial = send(alerts(box.port), history)
    assert partial.status == "sent" and box.messages[0]["rcpt_tos"] == ["quality@localhost"]


def test_a_server_that_is_down_or_silent_keeps_the_alert_for_the_next_run(tmp_path, history):
    port = free_port()
    first, down = send(alerts(port, attempts=2), history)
    assert (down.status, down.attempts) == ("pending", 2)
    with SilentServer() as silent, open_history(tmp_path / "other.db") as other:
        _, silent_result = send(alerts(silent.port, attempts=1, timeout_s=0.3), other)
    assert silent_result.status == "pending" and "timed out" in silent_result.error
    with Mailbox(port=port) as box:
        second, tonight = send(alerts(port), history, state="warning", verdict="drifting")
    assert [o.status for o in second.backlog] == ["sent"] and tonight.status == "sent"
    ids = [
        json.loads(body_text(m["message"]).split("\n\n", 1)[1])["alert_id"] for m in box.messages
    ]
    assert ids == [first.alert.alert_id, second.alert.alert_id]
    assert history.outbox("mill-3") == []


def test_header_injection_through_the_machine_id_is_neutralised(history):
    machine = "mill-3\r\nBcc: thief@localhost\r\nX-Evil: 1"
    with Mailbox() as box:
        _, result = send(alerts(box.port, to=["maint@localhost"]), history, machine_id=machine)
    assert result.status == "sent"
    (mail,) = box.messages
    msg = mail["message"]
    assert mail["rcpt_tos"] == ["maint@localhost"]
    assert msg["Bcc"] is None and msg["X-Evil"] is None
    assert msg["Subject"] == "[imu-square] mill-3 Bcc: thief@localhost X-Evil: 1: alarm"
    assert msg["X-Imu-Square-Machine-Id"] == "mill-3 Bcc: thief@localhost X-Evil: 1"
    # The body keeps the id exactly as it was given.
    attachment = next(msg.iter_attachments())
    assert json.loads(attachment.get_content())["machine_id"] == machine


def test_a_long_display_name_with_specials_keeps_its_quotes(history):
    # Python's 78-column refolding drops these quotes (CPython gh-80222), and "a; b" then
    # reads as a group: the sink never refolds headers shorter than RFC 5322's 998 limit.
    name = "Maintenance; hall 2 (night shift), the long name that a shop really writes here"
    with Mailbox() as box:
        _, result = send(alerts(box.port, to=[f'"{name}" <maint@localhost>']), history)
    assert result.status == "sent"
    to = box.messages[0]["message"]["To"]
    assert to.defects == ()
    assert [(a.display_name, a.addr_spec) for a in to.addresses] == [(name, "maint@localhost")]
