"""Real servers on localhost for the alert-sink tests: HTTP receiver, SMTP server, TLS cert."""

import json
import shutil
import socket
import ssl
import subprocess
import threading
import time
from email import message_from_bytes, policy
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest


def free_port():
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def self_signed_cert(folder):
    """A self-signed certificate for 127.0.0.1 and localhost, made with the openssl CLI.

    Returns
    -------
    (Path, Path)
        The certificate (also the CA bundle a client trusts) and its key.
    """
    openssl = shutil.which("openssl")
    if openssl is None:
        pytest.skip("the openssl command is not installed (Debian package openssl)")
    cert, key = folder / "cert.pem", folder / "key.pem"
    subprocess.run(
        [openssl, "req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1",
         "-nodes", "-keyout", str(key), "-out", str(cert), "-days", "2", "-subj", "/CN=localhost",
         "-addext", "subjectAltName=DNS:localhost,IP:127.0.0.1"],
        check=True, capture_output=True,
    )  # fmt: skip
    return cert, key


def server_tls_context(cert, key):
    """A server-side TLS context for the certificate."""
    context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    context.load_cert_chain(cert, key)
    return context


class Hook:
    """A real HTTP server on 127.0.0.1 that records every request.

    Parameters
    ----------
    replies : list
        Replies to the first requests, in order: a status, or (status, headers).
        Later requests get 200.
    port : int, optional
        Port to listen on (a free one by default).
    tls : ssl.SSLContext, optional
        Serve https with this context.
    hold : threading.Event, optional
        If given, every request waits for it before the reply (a hanging server).
    delay_s : float
        Time every reply takes. [s]
    """

    def __init__(self, replies=(), port=None, tls=None, hold=None, delay_s=0.0):
        self.replies = list(replies)
        self.requests = []
        self.arrived = threading.Event()
        self.hold = hold
        hook = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self):
                body = self.rfile.read(int(self.headers.get("Content-Length", 0)))
                hook.requests.append(
                    {
                        "path": self.path,
                        "headers": self.headers,
                        "body": body,
                        "t": time.monotonic(),
                    }
                )
                hook.arrived.set()
                if hook.hold is not None:
                    hook.hold.wait(30)
                time.sleep(delay_s)
                reply = hook.replies.pop(0) if hook.replies else 200
                status, headers = reply if isinstance(reply, tuple) else (reply, {})
                self.send_response(status)
                for key, value in headers.items():
                    self.send_header(key, value)
                self.send_header("Content-Length", "2")
                self.end_headers()
                self.wfile.write(b"ok")

            def log_message(self, *args):
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", port or 0), Handler)
        self.server.daemon_threads = True
        if tls is not None:
            self.server.socket = tls.wrap_socket(self.server.socket, server_side=True)
        self.port = self.server.server_address[1]
        self.scheme = "https" if tls is not None else "http"
        self.thread = threading.Thread(
            target=self.server.serve_forever, kwargs={"poll_interval": 0.02}, daemon=True
        )

    @property
    def url(self):
        """The server's base URL."""
        return f"{self.scheme}://127.0.0.1:{self.port}"

    def bodies(self):
        """The JSON bodies received, in order."""
        return [json.loads(r["body"]) for r in self.requests]

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        if self.hold is not None:
            self.hold.set()
        self.server.shutdown()
        self.server.server_close()


class Mailbox:
    """A real SMTP server (aiosmtpd) on 127.0.0.1 that keeps every message.

    Parameters
    ----------
    rcpt_replies : list of str
        Replies to the first RCPT commands (e.g. ``"451 try later"``); later
        ones are accepted.
    login : (bytes, bytes), optional
        Require AUTH with this username and password.
    tls : ssl.SSLContext, optional
        Offer STARTTLS (and require it) with this context.
    implicit_tls : ssl.SSLContext, optional
        Speak TLS from the first byte (SMTPS).
    port : int, optional
        Port to listen on.
    """

    def __init__(self, rcpt_replies=(), login=None, tls=None, implicit_tls=None, port=None):
        from aiosmtpd.controller import Controller
        from aiosmtpd.smtp import AuthResult

        self.messages = []
        self.logins = []
        self.rcpt_replies = list(rcpt_replies)
        box = self

        class Handler:
            async def handle_RCPT(self, server, session, envelope, address, options):
                if box.rcpt_replies:
                    return box.rcpt_replies.pop(0)
                envelope.rcpt_tos.append(address)
                return "250 OK"

            async def handle_DATA(self, server, session, envelope):
                box.messages.append(
                    {
                        "mail_from": envelope.mail_from,
                        "rcpt_tos": list(envelope.rcpt_tos),
                        "message": message_from_bytes(envelope.content, policy=policy.default),
                        # session.ssl after STARTTLS; the transport's ssl_object for SMTPS.
                        "tls": session.ssl is not None
                        or server.transport.get_extra_info("ssl_object") is not None,
                    }
                )
                return "250 Message accepted"

        def authenticator(server, session, envelope, mechanism, auth_data):
            self.logins.append((auth_data.login, auth_data.password))
            # handled=False: aiosmtpd itself then answers a failure with 535.
            return AuthResult(success=(auth_data.login, auth_data.password) == login, handled=False)

        kwargs = {"enable_SMTPUTF8": True}
        if login is not None:
            # aiosmtpd counts only STARTTLS as TLS, so SMTPS and plain tests must not require it.
            kwargs.update(authenticator=authenticator, auth_required=True,
                          auth_require_tls=tls is not None)  # fmt: skip
        if tls is not None:
            kwargs.update(tls_context=tls, require_starttls=True)
        if implicit_tls is not None:
            kwargs.update(ssl_context=implicit_tls)
        self.port = port or free_port()
        self.controller = Controller(Handler(), hostname="127.0.0.1", port=self.port, **kwargs)

    def __enter__(self):
        self.controller.start()
        return self

    def __exit__(self, *exc):
        self.controller.stop()


class SilentServer:
    """A socket that listens and never accepts: a connection succeeds and no answer ever comes."""

    def __init__(self):
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(16)
        self.port = self.sock.getsockname()[1]

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.sock.close()
