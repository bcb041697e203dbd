"""An emulated accelerometer board behind a pseudo-terminal.

The board streams a simulated circle test (:func:`imu_square.simulate.simulate_run`)
through the wire protocol, in real time on its own sample clock (``speed``
times faster if asked), quantised to counts with the sensor's ADC step. Like a
USB CDC board it transmits only while a host holds the port open: it starts
its sample clock when the first host connects (after the host asks for the
header, or 0.5 s after it opens the port), sends its header on connect, on
request and every second, and loses the samples it produces while no host
listens. Markers ``block_start DIR N`` and ``block_end DIR N`` go out at the
true start and end of motion of each block, as a CNC's M-code line would.

The slave end of the pty is symlinked at a stable path (like
``/dev/serial/by-id/...``); an unplugging removes the link and closes the pty,
and the board comes back on a new pty behind the same link. Faults come from
:mod:`acquisition.faults`; every frame's fate is logged in a
:class:`~acquisition.faults.FaultLog`, settled by a
:class:`~acquisition.faults.ReadBack` that parses the bytes as they go on the
wire, so a frame is logged as sent exactly when a host's parser gets it
intact. Before a planned unplugging the board waits until the host has read
everything, so the log is exact; when the host itself closes the port, the
bytes still in the pty at that moment are logged as sent but never read.
"""

import fcntl
import math
import os
import select
import struct
import termios
import threading
import time
import tty
from dataclasses import replace
from pathlib import Path

import numpy as np

from acquisition.faults import (
    DAMAGED,
    NO_HOST,
    OVERFLOW,
    SENT,
    FaultInjector,
    FaultPlan,
    ReadBack,
)
from acquisition.protocol import (
    INT24_MAX,
    INT24_MIN,
    REQUEST_HEADER,
    SAMPLES_PER_FRAME,
    SEQ_MODULUS,
    DeviceHeader,
    Marker,
    SampleBlock,
    check_header,
    encode_block,
    encode_header,
    encode_marker,
)
from imu_square import __version__
from imu_square.errors import AcquisitionError
from imu_square.log import logger
from imu_square.simulate import simulate_run
from imu_square.units import UG
from imu_square.validation import check_option

DEFAULT_SCALE_M_S2 = 3.9 * UG  # one count of an ADXL355 at +-2 g
HEADER_INTERVAL_S = 1.0
HOST_GRACE_S = 0.5
DRAIN_TIMEOUT_S = 2.0
DRAIN_SETTLE_S = 0.03
TX_BUFFER_BYTES = 64 * 1024
_POLL_S = 0.005


def quantise(accel, scale_m_s2):
    """Counts the board's ADC gives for ``accel``, rounded and clipped to int24.

    Parameters
    ----------
    accel : ndarray, shape (n, 3)
        Acceleration. [m/s^2]
    scale_m_s2 : float
        Acceleration of one count. [m/s^2]

    Returns
    -------
    ndarray of int32, shape (n, 3)
    """
    counts = np.rint(np.asarray(accel, np.float64) / scale_m_s2)
    return np.clip(counts, INT24_MIN, INT24_MAX).astype(np.int32)


def _name(text, fallback):
    clean = "".join(c for c in str(text) if 32 <= ord(c) < 127 and c not in ",=*")[:32]
    return clean or fallback


class EmulatedBoard:
    """A board that streams a recording through a pseudo-terminal.

    Parameters
    ----------
    recording : Recording
        The samples to stream (float, m/s^2) with their block events.
    link : str or Path
        Where the pty's slave end is symlinked.
    speed : float
        How many times faster than real time to stream.
    mode : {"binary", "line"}
        Wire mode.
    faults : FaultPlan
        Faults to inject.
    seed : int
        Seed of the fault randomness.
    clock_factor : float
        Sensor clock time per true time, ``1 + ppm * 1e-6``: the board sends
        its samples this much faster than nominal.
    seq_start : int
        Sequence number of the first sample (the counter wraps at 2**32).
    samples_per_frame : int
        Samples per binary frame.
    linger_s : float
        After the last sample, how long to wait for the host to close the port. [s]

    Attributes
    ----------
    counts : ndarray of int32, shape (n, 3)
        The samples as the board sends them. [counts]
    seq : ndarray of int64, shape (n,)
        Their unwrapped sequence numbers.
    header : DeviceHeader
        What the board says about itself.
    log : FaultLog
        What was sent, damaged and lost.
    ready : threading.Event
        Set once the link exists.
    """

    def __init__(
        self,
        recording,
        link,
        *,
        speed=1.0,
        mode="binary",
        faults=None,
        seed=0,
        clock_factor=1.0,
        seq_start=0,
        samples_per_frame=SAMPLES_PER_FRAME,
        linger_s=10.0,
    ):
        check_option("mode", mode, ("binary", "line"))
        if not (math.isfinite(speed) and speed > 0):
            raise AcquisitionError(f"speed must be a finite number > 0, got {speed!r}")
        sensor = recording.sensor
        scale = sensor.resolution_m_s2
        scale = scale if math.isfinite(scale) and scale > 0 else DEFAULT_SCALE_M_S2
        full_scale = sensor.range_m_s2
        full_scale = full_scale if math.isfinite(full_scale) else INT24_MAX * scale
        self.header = check_header(
            DeviceHeader(
                model=_name(sensor.model, "emulated"),
                serial=_name(sensor.serial, "emulated")[:32],  # the simulated sensor's identity
                firmware=f"imu-square-emulator-{__version__}"[:32],
                sample_rate_hz=recording.sample_rate_hz,
                dt_ns=recording.dt_ns,
                scale_m_s2_per_count=scale,
                range_m_s2=full_scale,
                noise_density_m_s2_rthz=sensor.noise_density_m_s2_rthz,
                has_temperature=recording.temperature_c is not None,
                mode=mode,
            )
        )
        self.counts = quantise(recording.accel, scale)
        self.temperature_c = recording.temperature_c  # sent once a block, as a board does
        self.seq = seq_start + np.arange(len(self.counts), dtype=np.int64)
        self.link = Path(link)
        self.mode = mode
        self.speed = float(speed)
        self.period_s = recording.dt_ns * 1e-9 / (clock_factor * self.speed)
        self.samples_per_frame = samples_per_frame if mode == "binary" else 1
        self.linger_s = linger_s
        self.faults = faults if faults is not None else FaultPlan()
        self._rng = np.random.default_rng(seed)
        self._injector = FaultInjector(self.faults, len(self.counts), self._rng)
        self.log = self._injector.log
        self._readback = ReadBack(self.log, mode)
        self._markers = self._marker_schedule(recording)
        self._disconnects = [
            (round(at / (recording.dt_ns * 1e-9)), max(1, round(length / (recording.dt_ns * 1e-9))))
            for at, length in self.faults.disconnects
        ]
        self.ready = threading.Event()
        self._stop = threading.Event()
        self._master = None
        self._slave_name = None

    def _marker_schedule(self, recording):
        """(sample index, text) of each block marker, in order."""
        out = []
        t0 = int(recording.time_ns[0])
        for event in recording.events:
            if event.kind in ("block_start", "block_end"):
                index = math.ceil((event.time_ns - t0) / recording.dt_ns)
                if 0 <= index < len(self.counts):
                    out.append((index, f"{event.kind} {event.direction} {event.block}"))
        return sorted(out)

    def stop(self):
        """Ask :meth:`run` to return soon; safe from another thread."""
        self._stop.set()

    # -- the pseudo-terminal -----------------------------------------------------------------

    def _check_link(self):
        if not self.link.parent.is_dir():
            raise AcquisitionError(
                f"link {str(self.link)!r}: folder {str(self.link.parent)!r} does not exist"
            )
        if self.link.exists() and not self.link.is_symlink():
            raise AcquisitionError(
                f"link {str(self.link)!r} exists and is not a symlink; refusing to replace it"
            )

    def _plug(self):
        master, slave = os.openpty()
        tty.setraw(slave)
        self._slave_name = os.ttyname(slave)
        os.close(slave)
        os.set_blocking(master, False)
        self._master = master
        self._poll = select.poll()
        self._poll.register(master, select.POLLIN)
        tmp = self.link.with_name(self.link.name + ".tmp")
        tmp.unlink(missing_ok=True)
        os.symlink(self._slave_name, tmp)
        os.replace(tmp, self.link)
        logger.info("emulated board on %s -> %s", self.link, self._slave_name)

    def _unplug(self):
        self.link.unlink(missing_ok=True)
        if self._master is not None:
            os.close(self._master)
            self._master = None

    def _host_present(self):
        """(present, bytes the host sent) from one poll of the master end."""
        events = self._poll.poll(0)
        if not events:
            return True, b""
        mask = events[0][1]
        data = b""
        if mask & select.POLLIN:
            try:
                data = os.read(self._master, 4096)
            except OSError:
                data = b""
        return not (mask & select.POLLHUP), data

    def _unread_by_host(self):
        """Bytes written to the pty that the host has not read yet."""
        try:
            fd = os.open(self._slave_name, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError:
            return 0
        try:
            return struct.unpack("i", fcntl.ioctl(fd, termios.FIONREAD, b"\0\0\0\0"))[0]
        finally:
            os.close(fd)

    # -- streaming -----------------------------------------------------------------------------

    def run(self):
        """Stream the whole recording, then wait for the host to let go; remove the link.

        Returns
        -------
        FaultLog
            What was sent, damaged and lost.
        """
        self._check_link()
        self._plug()
        self.ready.set()
        try:
            self._stream()
        finally:
            self._unplug()
            self._readback.finish()
        return self.log

    def _stream(self):
        tx = _TxBuffer()
        try:
            self._stream_into(tx)
        finally:  # what never left the board's buffer never reached the host
            self._refate(tx.clear(), NO_HOST)

    def _stream_into(self, tx):
        n = len(self.counts)
        connected_at = None  # monotonic time the current host opened the port
        streaming = False
        t0 = None  # monotonic time of sample 0
        index = 0
        next_header = 0
        marker_i = 0
        down = None  # (first index, end index) of an unplugging in progress
        disconnects = list(self._disconnects)
        lost_run = None  # first index of the current run of NO_HOST frames after a start
        while not self._stop.is_set():
            now = time.monotonic()
            if self._master is not None:
                present, data = self._host_present()
                if present and connected_at is None:
                    connected_at = now
                if not present and connected_at is not None:
                    connected_at, streaming = None, False
                    self._refate(tx.clear(), NO_HOST)
                if connected_at is not None and not streaming:
                    if REQUEST_HEADER[:1] in data or now - connected_at >= HOST_GRACE_S:
                        streaming = True
                        self._readback.restart()  # the host starts a fresh parser too
                        self._send(tx, encode_header(self.header))
                        if t0 is None:
                            t0 = now
                elif streaming and REQUEST_HEADER[:1] in data:
                    self._send(tx, encode_header(self.header))
            if t0 is None:
                time.sleep(_POLL_S)
                continue
            if index >= n:
                if not streaming or now - t0 - n * self.period_s > self.linger_s:
                    return
                self._write(tx)
                time.sleep(_POLL_S)
                continue
            due = min(n, int((now - t0) / self.period_s) + 1)
            while index < due:
                if disconnects and down is None and index >= disconnects[0][0]:
                    length = disconnects.pop(0)[1]
                    self._drain(tx)
                    self._unplug()
                    connected_at, streaming = None, False
                    down = (index, index + length)
                    lost_run = index
                if down is not None and index >= down[1]:
                    self._plug()
                    down = None
                stop = min(index + self.samples_per_frame, n)
                if stop > due and due < n:
                    break
                if stop - 1 >= next_header and streaming:
                    self._send(tx, encode_header(self.header))
                    next_header = index + round(HEADER_INTERVAL_S * 1e9 / self.header.dt_ns)
                self._frame(index, stop, streaming, tx)
                if streaming and lost_run is not None:
                    self.log.disconnects.append((int(self.seq[lost_run]), index - lost_run))
                    lost_run = None
                while marker_i < len(self._markers) and self._markers[marker_i][0] < stop:
                    at, text = self._markers[marker_i]
                    if streaming:
                        raw = int(self.seq[at]) % SEQ_MODULUS
                        self._send(tx, encode_marker(Marker(raw, text), self.mode))
                    marker_i += 1
                index = stop
            self._write(tx)
            wait = t0 + (index + self.samples_per_frame) * self.period_s - time.monotonic()
            time.sleep(min(max(wait, 0.0), _POLL_S))

    def _frame(self, start, stop, streaming, tx):
        """Encode samples [start, stop), damage them as planned, queue or lose them."""
        seq0 = int(self.seq[start])
        if not streaming:
            self.log.add_frame(seq0, stop - start, NO_HOST)
            return
        garbage = self._injector.garbage_before(start, seq0)
        if garbage:
            self._send(tx, garbage)
        temperature = math.nan
        if self.temperature_c is not None:
            temperature = round(float(self.temperature_c[start]), 2)
        block = SampleBlock(seq0 % SEQ_MODULUS, self.counts[start:stop], temperature_c=temperature)
        data = encode_block(block, self.mode)
        pieces = [data] if self.mode == "binary" else data.splitlines(keepends=True)
        n_here = stop - start if self.mode == "binary" else 1
        for k, piece in enumerate(pieces):
            wire, damaged = self._injector.damage(piece, delimited=self.mode == "binary")
            entry = len(self.log.seq0)
            self.log.add_frame(seq0 + k, n_here, DAMAGED if damaged else SENT)
            counts = self.counts[start + k : start + k + n_here]
            if not self._send(tx, wire, entry, seq0 + k, counts):
                self.log.fate[entry] = OVERFLOW

    def _send(self, tx, data, entry=None, seq0=None, counts=None):
        """Queue bytes for the host and let the read-back parse them; False if refused."""
        if not tx.add(data, entry):
            return False
        self._readback.feed(data, entry, seq0, counts)
        return True

    def _refate(self, entries, fate):
        for entry in entries:
            self.log.fate[entry] = fate

    def _write(self, tx):
        if self._master is not None:
            tx.write(self._master)

    def _drain(self, tx):
        """Before an unplugging: let the host read everything already sent."""
        deadline = time.monotonic() + DRAIN_TIMEOUT_S
        empty_since = None
        while time.monotonic() < deadline:
            self._write(tx)
            if tx.pending or self._unread_by_host():
                empty_since = None
            elif empty_since is None:
                empty_since = time.monotonic()
            elif time.monotonic() - empty_since > DRAIN_SETTLE_S:
                # Empty for a while: nothing is left in the tty's flip buffer either.
                return
            time.sleep(_POLL_S)
        self._refate(tx.clear(), NO_HOST)


class _TxBuffer:
    """The board's transmit buffer: bytes waiting for the pty, with the frames they hold."""

    def __init__(self, limit=TX_BUFFER_BYTES):
        self.limit = limit
        self.data = bytearray()
        self.frames = []  # (end offset in data, log entry)

    @property
    def pending(self):
        """Bytes waiting. [B]"""
        return len(self.data)

    def add(self, data, entry=None):
        """Queue bytes; a frame (``entry`` given) that does not fit is refused."""
        if entry is not None and len(self.data) + len(data) > self.limit:
            return False
        self.data += data
        if entry is not None:
            self.frames.append((len(self.data), entry))
        return True

    def write(self, fd):
        """Write as much as the pty takes now, without blocking."""
        if not self.data:
            return
        try:
            n = os.write(fd, self.data)
        except OSError:  # full (non-blocking) or the host just hung up: retry later
            return
        del self.data[:n]
        self.frames = [(end - n, e) for end, e in self.frames if end - n > 0]

    def clear(self):
        """Drop everything queued; return the log entries of the frames dropped."""
        entries = [e for _, e in self.frames]
        self.data.clear()
        self.frames = []
        return entries


def emulated_board(
    program,
    machine=None,
    sensor=None,
    *,
    faults=None,
    seed=0,
    uptime_s=0.0,
    motion=None,
    **kwargs,
):
    """Simulate a test and build the board that streams it.

    Parameters
    ----------
    program : TestProgram
        The circle test.
    machine : MachineModel, optional
        The machine (ideal by default).
    sensor : SensorModel, optional
        The sensor (ideal by default); a fault ``clock_ppm`` replaces its
        sample clock error, so the data and the pacing agree.
    faults : FaultPlan, optional
        Faults to inject.
    seed : int
        Seed of the simulation's noise and of the faults.
    uptime_s : float
        How long the board has been powered when the test starts: its counter
        starts there and its sensor is that far into its warm-up. [s]
    motion : SampledMotion, optional
        The commanded motion (a controller's); our own trajectory if None.
    **kwargs
        Passed to :class:`EmulatedBoard` (``link``, ``speed``, ``mode``, ...).

    Returns
    -------
    board : EmulatedBoard
    truth : dict
        The simulator's truth.
    """
    from imu_square.simulate import SensorModel

    faults = faults if faults is not None else FaultPlan()
    sensor = sensor if sensor is not None else SensorModel()
    if faults.clock_ppm:
        sensor = replace(sensor, clock_ppm=faults.clock_ppm)
    recording, truth = simulate_run(
        program, machine, sensor, seed=seed, uptime_s=uptime_s, motion=motion
    )
    kwargs.setdefault("seq_start", int(recording.seq[0]))
    board = EmulatedBoard(
        recording, faults=faults, seed=seed, clock_factor=1 + sensor.clock_ppm * 1e-6, **kwargs
    )
    return board, truth
