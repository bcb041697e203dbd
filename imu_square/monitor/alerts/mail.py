"""The e-mail sink: one message per alert over SMTP.

Built on the standard library's :mod:`smtplib` and
:class:`email.message.EmailMessage`: they speak STARTTLS, implicit TLS,
AUTH and SMTPUTF8, and build correctly encoded MIME; a third-party mailer
would add a dependency for nothing the monitor needs.

The message: subject ``[imu-square] MACHINE_ID: STATE``; a text part with the
verdict and the alert as indented JSON; the same JSON attached as
``alert.json`` (``application/json``) for scripts; headers
``X-Imu-Square-State``, ``X-Imu-Square-Machine-Id`` and a ``Message-ID`` made
from the alert id, so that a retried alert threads as the same message.
Control characters in the machine id become spaces before they reach a header,
so no field can add a header (``Bcc:``) to the message.

``security``: ``"starttls"`` (port 587 by default) upgrades the connection
before anything else is said and fails if the server cannot; ``"ssl"`` (465)
is TLS from the first byte; ``"none"`` (25) is plain, for a relay on this
machine, and is refused with a login unless the host is the machine itself,
since the password would cross the network in clear. Certificates and host
names are always verified, against the system's CAs or ``ca_file``.

The password comes from the environment variable named by ``password_env``
or the first line of the file named by ``password_file``, read when the alert
is sent; it is never stored in the monitor file, the outbox or a log.

How a failure is taken: a refused or dropped connection, a timeout and SMTP
4xx replies are transient (retried, then kept in the outbox); SMTP 5xx
replies (a refused login, sender or recipient), a certificate that does not
verify, a server without STARTTLS and a missing password are configuration
errors, not retried. When the server takes some recipients and refuses
others, the alert counts as sent and the refused ones are logged.
"""

import smtplib
import socket
import ssl
from dataclasses import dataclass
from email import policy
from email.message import EmailMessage
from email.utils import format_datetime
from pathlib import Path

from imu_square.log import logger
from imu_square.monitor.alerts.alert import (
    DEFAULT_ALERT_STATES,
    STATES,
    DeliveryError,
    env_secret,
    one_line,
    tls_context,
)
from imu_square.monitor.alerts.webhook import is_loopback

SECURITY = ("starttls", "ssl", "none")
DEFAULT_PORTS = {"starttls": 587, "ssl": 465, "none": 25}
MAX_TIMEOUT_S = 120.0
_POLICY = policy.default.clone(max_line_length=998)
ADDRESS = "an e-mail address such as 'maint@example.com' or 'Maintenance <maint@example.com>'"


@dataclass(frozen=True)
class EmailSink:
    """Mail alerts over SMTP.

    Attributes
    ----------
    name : str
        The sink's name in outcomes and the outbox.
    states : tuple of str
        States that are mailed.
    host : str
        SMTP server.
    port : int
        SMTP port.
    security : str
        ``"starttls"``, ``"ssl"`` or ``"none"`` (module docstring).
    sender : str
        The From address.
    to : tuple of str
        Recipients.
    username : str or None
        Login, or None to send without AUTH.
    password_env : str or None
        Environment variable holding the password.
    password_file : Path or None
        File whose first line is the password.
    timeout_s : float
        Timeout of each socket operation. [s]
    ca_file : Path or None
        CA bundle to verify the server against instead of the system's.
    """

    name: str
    states: tuple
    host: str
    port: int
    security: str
    sender: str
    to: tuple
    username: str | None = None
    password_env: str | None = None
    password_file: Path | None = None
    timeout_s: float = 10.0
    ca_file: Path | None = None
    kind = "email"

    def deliver(self, alert, timeout_s=None):
        """Mail ``alert``.

        Parameters
        ----------
        alert : Alert
            The alert.
        timeout_s : float, optional
            Timeout of each socket operation; :attr:`timeout_s` by default. [s]

        Raises
        ------
        DeliveryError
            With ``permanent`` set for configuration errors (module docstring).
        """
        message = build_message(alert, self.sender, self.to)
        password = self._password() if self.username is not None else None
        timeout_s = timeout_s or self.timeout_s
        context = tls_context(self.ca_file)
        # gethostname, not smtplib's default getfqdn: a DNS lookup that can stall for seconds.
        helo = socket.gethostname() or "localhost"
        try:
            if self.security == "ssl":
                server = smtplib.SMTP_SSL(
                    self.host, self.port, helo, timeout=timeout_s, context=context
                )
            else:
                server = smtplib.SMTP(self.host, self.port, helo, timeout=timeout_s)
            with server:
                if self.security == "starttls":
                    server.starttls(context=context)
                if self.username is not None:
                    server.login(self.username, password)
                refused = server.send_message(message, self.sender, list(self.to))
        except smtplib.SMTPNotSupportedError as exc:
            raise DeliveryError(f"the server cannot do what is configured: {exc}", True) from None
        except smtplib.SMTPRecipientsRefused as exc:
            codes = [code for code, _ in exc.recipients.values()]
            raise DeliveryError(
                f"every recipient was refused: {_replies(exc.recipients)}",
                permanent=all(code >= 500 for code in codes),
            ) from None
        except smtplib.SMTPResponseException as exc:
            text = exc.smtp_error.decode("utf-8", "replace") if exc.smtp_error else ""
            raise DeliveryError(
                f"SMTP {exc.smtp_code} {text}".strip(), permanent=exc.smtp_code >= 500
            ) from None
        except ssl.SSLCertVerificationError as exc:
            raise DeliveryError(
                f"the server's certificate does not verify: {exc.verify_message}", True
            ) from None
        except (OSError, smtplib.SMTPException) as exc:  # refused, reset, timeout, dropped
            raise DeliveryError(f"no answer: {type(exc).__name__}: {exc}") from None
        if refused:
            logger.warning(
                "e-mail sink %s: the alert went out, but the server refused %s",
                self.name,
                _replies(refused),
            )

    def _password(self):
        if self.password_env is not None:
            password = env_secret(self.password_env, "password_env")
            where = f"the environment variable {self.password_env} (password_env)"
        else:
            where = f"password_file {self.password_file}"
            try:
                lines = self.password_file.read_text(encoding="utf-8").splitlines()
            except (OSError, UnicodeDecodeError) as exc:
                raise DeliveryError(f"cannot read {where}: {exc}", permanent=True) from None
            password = lines[0] if lines else ""
            if not password:
                raise DeliveryError(f"{where} has no password on its first line", True)
        if not password.isascii():
            raise DeliveryError(
                f"{where} must be ASCII (SMTP AUTH as smtplib speaks it)", permanent=True
            )
        return password

    def describe(self):
        """What the sink does, for messages (never the password)."""
        return f"mail to {', '.join(self.to)} via {self.host}:{self.port} ({self.security})"


def _replies(recipients):
    return "; ".join(
        f"{addr}: {code} {text.decode('utf-8', 'replace') if isinstance(text, bytes) else text}"
        for addr, (code, text) in recipients.items()
    )


def build_message(alert, sender, to):
    """The e-mail for one alert (module docstring).

    Parameters
    ----------
    alert : Alert
        The alert.
    sender : str
        The From address.
    to : sequence of str
        Recipients.

    Returns
    -------
    EmailMessage
    """
    # Fold only past RFC 5322's 998-character limit: Python before the fix of CPython
    # gh-80222 drops the quotes of a display name (one holding ';' or '(') when it refolds
    # an address header at 78 columns, which breaks the header and lets a name spoof one.
    message = EmailMessage(policy=_POLICY)
    message["Subject"] = f"[imu-square] {one_line(alert.machine_id)}: {alert.state}"
    message["From"] = sender
    message["To"] = ", ".join(to)
    message["Date"] = format_datetime(alert.created)
    message["Message-ID"] = f"<{alert.alert_id}@imu-square.invalid>"
    message["X-Imu-Square-State"] = alert.state
    message["X-Imu-Square-Machine-Id"] = one_line(alert.machine_id)
    text = alert.to_json(indent=2)
    message.set_content(f"{alert.verdict}\n\n{text.decode()}\n")
    message.add_attachment(text, maintype="application", subtype="json", filename="alert.json")
    return message


def _address(table, key, value):
    if not isinstance(value, str):
        table.fail(key, ADDRESS, value)
    try:
        header = policy.default.header_factory("To", value)
        ok = len(header.addresses) == 1 and not header.defects and "\n" not in value
    except (ValueError, IndexError):
        ok = False
    if not ok or "@" not in header.addresses[0].addr_spec:
        table.fail(key, ADDRESS, value)
    return value


def email_from_table(table, name, default_states=DEFAULT_ALERT_STATES):
    """An ``[alerts.email]`` table.

    Parameters
    ----------
    table : imu_square.validation.TomlTable
        The checked table.
    name : str
        The sink's name when the table does not give one.
    default_states : tuple of str
        States when the table does not list them.

    Returns
    -------
    EmailSink
    """
    host = table.text("host")
    security = table.choice("security", SECURITY, default="starttls")
    port = table.integer("port", 1, 65535, default=DEFAULT_PORTS[security])
    sender = _address(table, "sender", table.get("sender"))
    to = table.get("to", None)
    if not isinstance(to, list) or not to:
        table.fail("to", f"a non-empty list of addresses, each {ADDRESS}", to)
    to = tuple(_address(table, "to", addr) for addr in to)
    username = table.text("username", default=None)
    if username is not None and not username.isascii():
        # smtplib sends AUTH credentials as ASCII; anything else fails at every login.
        table.fail("username", "ASCII text (SMTP AUTH as smtplib speaks it)", username)
    password_env = table.env_name("password_env")
    password_file = table.path("password_file", default=None)
    if username is None and (password_env or password_file):
        table.error("sets a password but no username")
    if username is not None and (password_env is None) == (password_file is None):
        table.error("needs exactly one of password_env and password_file with a username")
    if username is not None and security == "none" and not is_loopback(host):
        table.fail(
            "security",
            "'starttls' or 'ssl' with a username (with 'none' the password would cross the "
            "network in clear; 'none' with a login is allowed only to localhost)",
            security,
        )
    return EmailSink(
        name=name,
        states=table.choices("states", STATES, default=default_states),
        host=host,
        port=port,
        security=security,
        sender=sender,
        to=to,
        username=username,
        password_env=password_env,
        password_file=password_file,
        timeout_s=table.number("timeout_s", 0.0, MAX_TIMEOUT_S, lo_open=True, default=10.0),
        ca_file=table.path("ca_file", default=None),
    )
