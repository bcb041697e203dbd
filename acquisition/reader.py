"""A serial reader thread that survives the board being unplugged.

pyserial's ``ReaderThread`` stops for good on the first error. A USB board
that is unplugged makes its device node disappear, and comes back under the
same stable name (``/dev/serial/by-id/...``, or the emulator's symlink). The
:class:`SerialSupervisor` therefore closes the port on ``SerialException`` or
``OSError``, waits (exponential back-off, capped), reopens the port by the
name it was given, and tells its owner about each connect and disconnect so
the owner can ask for a header and resynchronise its framing.

Everything the thread sees goes into one queue, in order:

- ``("connect", serial_port, host_ns)``
- ``("data", bytes, host_ns)``
- ``("disconnect", message, host_ns)``

``host_ns`` is :func:`time.monotonic_ns` at that moment, for diagnostics only.
"""

import os
import threading
import time

import serial

from imu_square.errors import AcquisitionError
from imu_square.log import logger

READ_SIZE = 65536


def open_port(port, baudrate, timeout_s):
    """Open a serial port (a device path, a pty or any pyserial URL).

    Parameters
    ----------
    port : str
        Device path or pyserial URL (``loop://``, ``socket://...``).
    baudrate : int
        Line speed (ignored by pseudo-terminals and USB CDC). [bit/s]
    timeout_s : float
        Read time-out. [s]

    Returns
    -------
    serial.SerialBase

    Raises
    ------
    AcquisitionError
        When the port cannot be opened, with pyserial's reason.
    """
    if "://" not in port and not os.path.exists(port):
        raise AcquisitionError(
            f"serial port {port!r} not found: is the board plugged in? "
            f"(stable names are in /dev/serial/by-id/)"
        )
    try:
        return serial.serial_for_url(port, baudrate=baudrate, timeout=timeout_s)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise AcquisitionError(f"cannot open serial port {port!r}: {exc}") from None


class SerialSupervisor:
    """Reads a serial port in a thread, reconnecting after every failure.

    Parameters
    ----------
    port : str
        Stable name of the port, reopened after each failure.
    baudrate : int
        Line speed. [bit/s]
    out : queue.Queue
        Receives the ``connect``/``data``/``disconnect`` items.
    backoff_s : float
        First wait before reopening. [s]
    backoff_max_s : float
        Longest wait between attempts. [s]
    timeout_s : float
        Read time-out, which bounds how long :meth:`stop` takes. [s]
    pace_s : float
        Pause after each read that returned data, so the kernel gathers the
        next bytes and the thread wakes ~50 times a second rather than once a
        frame; the port's buffer holds far more than that. [s]
    """

    def __init__(
        self,
        port,
        baudrate,
        out,
        *,
        backoff_s=0.02,
        backoff_max_s=1.0,
        timeout_s=0.05,
        pace_s=0.02,
    ):
        self.port = port
        self.baudrate = baudrate
        self.out = out
        self.backoff_s = backoff_s
        self.backoff_max_s = backoff_max_s
        self.timeout_s = timeout_s
        self.pace_s = pace_s
        self.reconnects = 0
        self._serial = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"serial {port}", daemon=True)
        self._write_lock = threading.Lock()

    def start(self):
        """Open the port once (raising if that fails) and start the reader thread.

        Raises
        ------
        AcquisitionError
            When the port cannot be opened at all.
        """
        self._connected(open_port(self.port, self.baudrate, self.timeout_s))
        self._thread.start()

    def stop(self):
        """Stop the thread and close the port; safe to call more than once."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()
        self._close()

    def write(self, data):
        """Send ``data`` to the board if connected; failures are left to the reader.

        Parameters
        ----------
        data : bytes
            Bytes to send.

        Returns
        -------
        bool
            True if the bytes were handed to the port.
        """
        with self._write_lock:
            port = self._serial
            if port is None:
                return False
            try:
                port.write(data)
            except (serial.SerialException, OSError):
                return False
            return True

    def _connected(self, port):
        with self._write_lock:
            self._serial = port
        self.out.put(("connect", port, time.monotonic_ns()))

    def _close(self):
        with self._write_lock:
            port, self._serial = self._serial, None
        if port is not None:
            try:
                port.close()
            except (serial.SerialException, OSError):
                pass

    def _run(self):
        wait = self.backoff_s
        while not self._stop.is_set():
            port = self._serial
            if port is None:
                try:
                    port = open_port(self.port, self.baudrate, self.timeout_s)
                except AcquisitionError as exc:
                    logger.debug("%s; retrying in %.2f s", exc, wait)
                    self._stop.wait(wait)
                    wait = min(2 * wait, self.backoff_max_s)
                    continue
                self.reconnects += 1
                logger.info("serial port %s reopened", self.port)
                self._connected(port)
                wait = self.backoff_s
            try:
                # Only what is there (or one byte, waiting up to the time-out): pyserial
                # drops what one read() has gathered when the port fails during it.
                data = port.read(min(port.in_waiting, READ_SIZE) or 1)
            except (serial.SerialException, OSError) as exc:
                logger.warning("serial port %s lost: %s", self.port, exc)
                self._close()
                self.out.put(("disconnect", str(exc), time.monotonic_ns()))
                continue
            if data:
                self.out.put(("data", data, time.monotonic_ns()))
                self._stop.wait(self.pace_s)
