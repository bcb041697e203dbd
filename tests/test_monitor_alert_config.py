"""The [alerts] section of the monitor file: defaults, every sink, one-line errors."""

import tomllib
from pathlib import Path

import pytest

from imu_square.errors import ConfigError, ImuSquareWarning, MonitorConfigError
from imu_square.monitor.alerts.alert import DEFAULT_ALERT_STATES, STATES
from imu_square.monitor.alerts.config import AlertsConfig, RetryPolicy, alerts_from_mapping

FULL = """
[alerts]
states = ["alarm", "stale_baseline"]
attempts = 3
backoff_s = 0.25
max_total_s = 6

[alerts.log]
states = ["alarm"]

[[alerts.json_file]]
path = "latest.json"

[[alerts.json_file]]
name = "all"
path = "~/alerts.jsonl"
mode = "append"
states = ["ok", "alarm"]

[[alerts.webhook]]
url = "https://hooks.example.com/imu/ü?x=1"
timeout_s = 2.5
headers = { "X-Shop" = "hall 2" }
token_env = "HOOK_TOKEN"

[[alerts.webhook]]
name = "slack"
url_env = "SLACK_URL"
states = ["ok"]

[alerts.email]
host = "smtp.example.com"
security = "ssl"
sender = "imu-square <noreply@example.com>"
to = ["maint@example.com", "Q <quality@example.com>"]
username = "imu"
password_file = "secrets/smtp"
ca_file = "/etc/ssl/private-ca.pem"
"""


HOOK = "[[alerts.webhook]]\nurl = 'https://x'\n"
MAIL = "[alerts.email]\nhost = 'h'\nsender = 'a@b'\nto = ['c@d']\n"


def parse(text, base_dir="/etc/imu"):
    doc = tomllib.loads(text)
    return alerts_from_mapping(doc.get("alerts"), "monitor.toml", base_dir)


def test_without_an_alerts_section_the_monitor_only_logs():
    config = alerts_from_mapping(None)
    assert config == AlertsConfig()
    assert [s.name for s in config.sinks] == ["log"]
    assert config.sinks[0].states == STATES
    assert config.retry == RetryPolicy(attempts=4, backoff_s=0.5, max_total_s=10.0)


def test_a_full_section_gives_every_sink_with_its_defaults_and_resolved_paths():
    config = parse(FULL)
    assert [s.name for s in config.sinks] == [
        "log", "json_file-1", "all", "webhook-1", "slack", "email",
    ]  # fmt: skip
    log, latest, every, hook, slack, mail = config.sinks
    assert config.retry == RetryPolicy(3, 0.25, 6.0)
    assert log.states == ("alarm",)
    # A sink without states takes [alerts] states; one with states keeps its own.
    assert latest.states == ("alarm", "stale_baseline") and latest.mode == "latest"
    assert latest.path == Path("/etc/imu/latest.json")
    assert every.path == Path.home() / "alerts.jsonl" and every.mode == "append"
    assert every.states == ("ok", "alarm")
    # Non-ASCII in the path is percent-encoded once, at parse time.
    assert hook.url == "https://hooks.example.com/imu/%C3%BC?x=1"
    assert hook.timeout_s == 2.5 and hook.headers == (("X-Shop", "hall 2"),)
    assert hook.token_env == "HOOK_TOKEN" and hook.token_header == "Authorization"
    assert slack.url is None and slack.url_env == "SLACK_URL" and slack.states == ("ok",)
    assert (mail.port, mail.security, mail.timeout_s) == (465, "ssl", 10.0)
    assert mail.to == ("maint@example.com", "Q <quality@example.com>")
    assert mail.password_file == Path("/etc/imu/secrets/smtp")
    assert mail.ca_file == Path("/etc/ssl/private-ca.pem")
    assert mail.states == ("alarm", "stale_baseline")


def test_an_old_outbox_folder_still_loads_with_one_warning_that_it_is_no_longer_used():
    # The pending alerts live in the history now; older monitor files name a folder.
    with pytest.warns(ImuSquareWarning) as caught:
        config = parse(FULL.replace("max_total_s = 6\n", 'max_total_s = 6\noutbox = "spool"\n'))
    assert [str(w.message) for w in caught] == [
        "monitor.toml: [alerts] outbox is no longer used: the pending alerts are kept in the "
        "history; remove the field"
    ]
    assert config == parse(FULL)


def test_default_states_alert_on_everything_but_ok_and_no_baseline():
    config = parse('[alerts.json_file]\npath = "a.json"\n')
    assert config.sinks[1].states == DEFAULT_ALERT_STATES
    assert "ok" not in DEFAULT_ALERT_STATES and "no_baseline" not in DEFAULT_ALERT_STATES


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[alerts]\nsatets = []", r"monitor.toml: \[alerts\] has unknown field 'satets'"),
        ('[alerts]\nstates = ["alarm", "panic"]', r"\[alerts\] states must be a list of distinct"),
        (
            "[alerts]\nattempts = 0",
            r"\[alerts\] attempts must be a whole number in \[1, 10\], got 0",
        ),
        ("[alerts]\nmax_total_s = 0", r"max_total_s must be in \(0, 300\], got 0"),
        ("[alerts]\nbackoff_s = true", r"backoff_s must be a number in \[0, 60\], got True"),
        ("[alerts]\njson_file = 3", r"\[alerts.json_file\] must be a table or an array of tables"),
        (
            "[alerts.json_file]\nmode = 'latest'",
            r"\[alerts.json_file\] is missing the required field 'path'",
        ),
        (
            "[alerts.json_file]\npath = 'a'\nmode = 'tail'",
            r"mode must be one of \('latest', 'append'\), got 'tail'",
        ),
        ("[alerts.json_file]\npath = ''", r"path must be a non-empty string on one line"),
        (
            "[[alerts.webhook]]\ntimeout_s = 1",
            r"\[\[alerts.webhook\]\] #1 needs exactly one of url and url_env",
        ),
        # each says once what is wrong (it used to read "must be an http(s) URL (must be ...)")
        (
            "[[alerts.webhook]]\nurl = 'ftp://x/y'",
            r"url must be an http:// or https:// URL with a host, got 'ftp://x/y'$",
        ),
        (
            "[[alerts.webhook]]\nurl = 'http://x/a b'",
            r"url must not hold spaces or control characters \(percent-encode them\), got",
        ),
        (
            "[[alerts.webhook]]\nurl = 'http://x:99999/'",
            r"url is not a valid URL: Port out of range 0-65535, got 'http://x:99999/'$",
        ),
        (HOOK + "timeout_s = 0", r"timeout_s must be in \(0, 120\], got 0"),
        (
            HOOK + "headers = {'X-A' = \"a\\r\\nX-B: b\"}",
            r"headers.X-A must be Latin-1 text without CR, LF",
        ),
        (HOOK + "headers = {'X-A' = '€'}", r"headers.X-A must be Latin-1 text"),
        (HOOK + "headers = {'Bad Name' = 'v'}", r"headers must be header names"),
        (HOOK + "headers = {'Content-Length' = '3'}", r"headers must be header names"),
        (HOOK + "token_env = '$(id)'", r"token_env must be an environment variable name"),
        (
            "[[alerts.webhook]]\nurl = 'http://hooks.example.com/'\ntoken_env = 'T'",
            r"url must be an https:// URL when token_env is set",
        ),
        (
            HOOK + "token_env = 'T'\nheaders = {'authorization' = 'x'}",
            r"token_header must be a header that headers does not also set",
        ),
        (
            HOOK + "[[alerts.webhook]]\nurl = 'https://y'\nname = 'webhook-1'",
            r"#2 name must be different from every other sink's name",
        ),
        (HOOK + "name = 'a/b'", r"name must be 1-64 letters"),
        (
            "[alerts.email]\nsender = 'a@b'\nto = ['c@d']",
            r"\[alerts.email\] is missing the required field 'host'",
        ),
        (
            "[alerts.email]\nhost = 'h'\nsender = 'nobody'\nto = ['c@d']",
            r"sender must be an e-mail address",
        ),
        (
            "[alerts.email]\nhost = 'h'\nsender = 'a@b'\nto = []",
            r"to must be a non-empty list of addresses",
        ),
        (
            "[alerts.email]\nhost = 'h'\nsender = 'a@b'\nto = ['c@d, e@f']",
            r"to must be an e-mail address",
        ),
        (MAIL + "security = 'tls'", r"security must be one of \('starttls', 'ssl', 'none'\)"),
        (MAIL + "port = 0", r"port must be a whole number in \[1, 65535\]"),
        (MAIL + "username = 'u'", r"needs exactly one of password_env and password_file"),
        (MAIL + "password_env = 'P'", r"sets a password but no username"),
        (MAIL + "username = 'ü'\npassword_env = 'P'", r"username must be .*ASCII"),
        (
            "[alerts.email]\nhost = 'mail.example.com'\nsender = 'a@b'\nto = ['c@d']\n"
            "security = 'none'\nusername = 'u'\npassword_env = 'P'",
            r"security must be 'starttls' or 'ssl' with a username",
        ),
        (MAIL + "subject = 'x'", r"\[alerts.email\] has unknown field 'subject'"),
    ],
)
def test_a_mistake_is_one_line_naming_the_field_the_rule_and_the_value(text, message):
    with pytest.raises(MonitorConfigError, match=message) as info:
        parse(text)
    assert "\n" not in str(info.value)
    assert isinstance(info.value, ConfigError)


def test_plain_smtp_with_a_login_and_plain_http_with_a_token_are_allowed_to_this_machine():
    config = parse(
        "[alerts.email]\nhost = 'localhost'\nsecurity = 'none'\nsender = 'a@b'\nto = ['c@d']\n"
        "username = 'u'\npassword_env = 'P'\n"
        "[[alerts.webhook]]\nurl = 'http://127.0.0.1:8080/h'\ntoken_env = 'T'\n"
    )
    assert config.sink("email").port == 25
    assert config.sink("webhook").url == "http://127.0.0.1:8080/h"
