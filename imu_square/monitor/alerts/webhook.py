"""The webhook sink: an HTTP POST of the alert's JSON.

Built on the standard library's :mod:`urllib.request`: one POST with a
timeout, custom headers and a TLS context is all it needs, and retries are the
monitor's own (:mod:`imu_square.monitor.alerts.send`), so a client library would add
a dependency and nothing else.

The request carries ``Content-Type: application/json; charset=utf-8``,
``User-Agent: imu-square/VERSION``, ``Idempotency-Key: ALERT_ID`` (the same on
every retry), the configured headers, and, if ``token_env`` names an
environment variable, ``TOKEN_HEADER: TOKEN_PREFIX + $TOKEN_ENV`` (by default
``Authorization: Bearer ...``). The token is read when the alert is sent and
is never stored in the monitor file, the outbox or a log.

How an answer is taken:

- 2xx: delivered.
- 408, 425, 429 and 5xx, a refused connection, a timeout: transient, retried
  with back-off (honouring ``Retry-After`` within the time cap), then kept in
  the outbox.
- 3xx: refused, not followed: urllib would turn the POST into a GET without
  the body, and a redirect may carry the token to another host. Put the
  final URL in the monitor file.
- any other 4xx, a certificate that does not verify, a missing token: a
  configuration error, not retried (the alert is kept in the outbox as
  ``rejected``).

HTTPS always verifies the server's certificate and host name, against the
system's trusted CAs or, with ``ca_file``, against that bundle only.
"""

import http.client
import ipaddress
import re
import ssl
import urllib.error
import urllib.parse
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path

from imu_square import __version__
from imu_square.monitor.alerts.alert import (
    DEFAULT_ALERT_STATES,
    STATES,
    DeliveryError,
    env_secret,
    tls_context,
)
from imu_square.validation import has_control_chars

MAX_TIMEOUT_S = 120.0
TRANSIENT_4XX = (408, 425, 429)
# Headers the client itself sets from the body and the URL.
RESERVED_HEADERS = ("content-length", "host", "transfer-encoding", "connection")
_TOKEN = re.compile(r"[!#$%&'*+\-.^_`|~0-9A-Za-z]+")  # RFC 9110 header-name characters
HEADER_TEXT = (
    "Latin-1 text without CR, LF or other control characters (HTTP sends header values "
    "as bytes; ASCII is safest)"
)
CLEAR_TOKEN = (
    "an https:// URL when token_env is set (over http:// the token would cross the network "
    "in clear; plain http is allowed only to localhost)"
)
_READ_LIMIT = 4096  # bytes of a reply kept for the log


@dataclass(frozen=True)
class WebhookSink:
    """POST alerts to a URL.

    Attributes
    ----------
    name : str
        The sink's name in outcomes and the outbox.
    states : tuple of str
        States that are sent.
    url : str or None
        The URL (non-ASCII already percent-encoded), or None if ``url_env``
        gives it.
    url_env : str or None
        Environment variable holding the URL, for services whose URL is itself
        the secret (Slack, Teams).
    timeout_s : float
        Timeout of each socket operation (connect, send, each read). [s]
    headers : tuple of (str, str)
        Extra headers.
    token_env : str or None
        Environment variable holding a secret token.
    token_header : str
        Header that carries the token.
    token_prefix : str
        Text before the token in that header.
    ca_file : Path or None
        CA bundle to verify an https server against instead of the system's.
    """

    name: str
    states: tuple
    url: str | None
    url_env: str | None = None
    timeout_s: float = 5.0
    headers: tuple = field(default=())
    token_env: str | None = None
    token_header: str = "Authorization"
    token_prefix: str = "Bearer "
    ca_file: Path | None = None
    kind = "webhook"

    def deliver(self, alert, timeout_s=None):
        """POST ``alert``.

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
        url = self._url()
        request = urllib.request.Request(
            url, data=alert.to_json(), headers=self._headers(alert), method="POST"
        )
        handlers = [_RefuseRedirect()]
        if url.lower().startswith("https:"):
            handlers.append(urllib.request.HTTPSHandler(context=tls_context(self.ca_file)))
        opener = urllib.request.build_opener(*handlers)
        try:
            with opener.open(request, timeout=timeout_s or self.timeout_s) as reply:
                reply.read(_READ_LIMIT)
        except urllib.error.HTTPError as exc:
            raise _http_error(exc) from None
        except urllib.error.URLError as exc:
            if isinstance(exc.reason, ssl.SSLCertVerificationError):
                raise DeliveryError(
                    f"the server's certificate does not verify: {exc.reason.verify_message}",
                    permanent=True,
                ) from None
            raise DeliveryError(f"cannot reach the server: {exc.reason}") from None
        except (OSError, http.client.HTTPException) as exc:  # timeouts, resets, bad replies
            raise DeliveryError(f"no answer: {type(exc).__name__}: {exc}") from None

    def _url(self):
        if self.url is not None:
            return self.url
        try:
            url = check_url(env_secret(self.url_env, "url_env"))
        except ValueError as exc:
            raise DeliveryError(f"${self.url_env} {exc}", permanent=True) from None
        if self.token_env is not None and _clear_to_network(url):
            raise DeliveryError(f"${self.url_env} must be {CLEAR_TOKEN}", permanent=True)
        return url

    def _headers(self, alert):
        headers = {
            "Content-Type": "application/json; charset=utf-8",
            "User-Agent": f"imu-square/{__version__}",
            "Idempotency-Key": alert.alert_id,
        }
        headers.update(self.headers)
        if self.token_env is not None:
            token = env_secret(self.token_env, "token_env")
            if not is_header_text(token):
                # A CR/LF in a header value would let the variable inject headers.
                raise DeliveryError(
                    f"the environment variable {self.token_env} (token_env) must be {HEADER_TEXT}",
                    permanent=True,
                )
            headers[self.token_header] = self.token_prefix + token
        return headers

    def describe(self):
        """What the sink does, for messages (the URL without its query, never the token)."""
        if self.url is None:
            return f"the webhook in ${self.url_env}"
        parts = urllib.parse.urlsplit(self.url)
        return f"{parts.scheme}://{parts.netloc}{parts.path}"


class _RefuseRedirect(urllib.request.HTTPRedirectHandler):
    def redirect_request(self, req, fp, code, msg, headers, newurl):
        return None  # urllib then raises the 3xx as an HTTPError


def _http_error(exc):
    code = exc.code
    try:
        text = exc.read(_READ_LIMIT).decode("utf-8", "replace").strip().splitlines()
    except OSError:
        text = []
    finally:
        exc.close()
    reply = f"HTTP {code} {exc.reason}" + (f": {text[0][:200]}" if text else "")
    if 300 <= code < 400:
        where = exc.headers.get("Location", "?")
        return DeliveryError(
            f"{reply}; redirects are not followed, put the final URL ({where}) in the monitor file",
            permanent=True,
        )
    if code in TRANSIENT_4XX or code >= 500:
        return DeliveryError(reply, retry_after_s=_retry_after(exc.headers.get("Retry-After")))
    return DeliveryError(f"{reply} (a configuration error: check url, headers and token)", True)


def _retry_after(value):
    """Seconds from a ``Retry-After`` header given in seconds; None for a date or garbage."""
    try:
        seconds = float(value)
    except (TypeError, ValueError):
        return None
    return seconds if 0 <= seconds < 86400 else None


def _clear_to_network(url):
    """Whether ``url`` is plain http to another machine."""
    parts = urllib.parse.urlsplit(url)
    return parts.scheme.lower() == "http" and not is_loopback(parts.hostname)


def is_header_text(text):
    """Whether ``text`` can be an HTTP header value as it is (see :data:`HEADER_TEXT`).

    Parameters
    ----------
    text : str
        The value.

    Returns
    -------
    bool
    """
    try:
        text.encode("latin-1")
    except UnicodeEncodeError:
        return False
    return not has_control_chars(text)


def is_loopback(host):
    """Whether ``host`` names this machine (``localhost`` or a loopback address).

    Parameters
    ----------
    host : str
        Host name or IP address.

    Returns
    -------
    bool
    """
    if host.lower().rstrip(".") == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def check_url(url):
    """Check an http(s) URL and percent-encode any non-ASCII text after the host.

    Parameters
    ----------
    url : str
        The URL.

    Returns
    -------
    str
        The URL as it will be requested.

    Raises
    ------
    ValueError
        Saying what is wrong with it.
    """
    if has_control_chars(url) or " " in url:
        raise ValueError("must not hold spaces or control characters (percent-encode them)")
    try:
        parts = urllib.parse.urlsplit(url)
        hostname = parts.hostname
        parts.port  # noqa: B018 -- raises ValueError on a bad port
    except ValueError as exc:
        raise ValueError(f"is not a valid URL: {exc}") from None
    if parts.scheme.lower() not in ("http", "https") or not hostname:
        raise ValueError("must be an http:// or https:// URL with a host")
    safe = "".join(chr(c) for c in range(33, 127))  # keep every printable ASCII as written
    return urllib.parse.urlunsplit(
        parts._replace(
            path=urllib.parse.quote(parts.path, safe=safe),
            query=urllib.parse.quote(parts.query, safe=safe),
            fragment="",
        )
    )


def webhook_from_table(table, name, default_states=DEFAULT_ALERT_STATES):
    """A ``[[alerts.webhook]]`` table.

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
    WebhookSink
    """
    if table.has("url") == table.has("url_env"):
        table.error("needs exactly one of url and url_env")
    url = None
    if table.has("url"):
        try:
            url = check_url(table.text("url"))
        except ValueError as exc:  # it says what the URL must be, or what is wrong with it
            table.error(f"url {exc}, got {table.get('url', None)!r}")
    headers = table.get("headers", {})
    if not isinstance(headers, dict):
        table.fail("headers", "a table of header names to string values", headers)
    for key, value in headers.items():
        if not _TOKEN.fullmatch(key) or key.lower() in RESERVED_HEADERS:
            table.fail(
                "headers",
                f"header names made of RFC 9110 token characters, not {RESERVED_HEADERS}",
                key,
            )
        if not isinstance(value, str) or not is_header_text(value):
            table.fail(f"headers.{key}", HEADER_TEXT, value)
    token_env = table.env_name("token_env")
    token_header = table.text("token_header", default="Authorization")
    token_prefix = table.text("token_prefix", default="Bearer ", empty=True)
    if not is_header_text(token_prefix):
        table.fail("token_prefix", HEADER_TEXT, token_prefix)
    if not _TOKEN.fullmatch(token_header) or token_header.lower() in RESERVED_HEADERS:
        table.fail("token_header", "a header name (RFC 9110 token characters)", token_header)
    if token_env is not None and token_header.lower() in (k.lower() for k in headers):
        table.fail("token_header", "a header that headers does not also set", token_header)
    if token_env is not None and url is not None and _clear_to_network(url):
        table.fail("url", CLEAR_TOKEN, url)
    return WebhookSink(
        name=name,
        states=table.choices("states", STATES, default=default_states),
        url=url,
        url_env=table.env_name("url_env"),
        timeout_s=table.number("timeout_s", 0.0, MAX_TIMEOUT_S, lo_open=True, default=5.0),
        headers=tuple(headers.items()),
        token_env=token_env,
        token_header=token_header,
        token_prefix=token_prefix,
        ca_file=table.path("ca_file", default=None),
    )
