"""Record a board's stream into an MCAP file while it arrives.

The :class:`Recorder` runs in the calling thread; a :class:`SerialSupervisor`
thread reads the port and reconnects after every failure. The recorder parses
the bytes, unwraps the board's sequence numbers (the time base: sample ``seq``
is at ``t_start_ns + (seq - seq_first) * dt_ns`` on the board's clock), waits
for the trigger while keeping a pre-trigger buffer, and streams samples and
events to a :class:`~imu_square.io.mcap.RecordingWriter`, which it flushes
(chunk closed, fsync) every second, so a kill or a power cut loses at most
the last second. A bad sample is never written or interpolated: damaged
frames are dropped by the parser, counted, and leave a ``gap`` event with the
number of samples lost (``lost=N,lost_s=T``).

A board that goes away for good never makes a clean run. When no sample has
arrived for ``silence_timeout_s`` (the port stayed lost, or the board hung),
or when the planned stop passes while the board is silent, the recorder
stops with ``stop_reason`` ``"port lost"`` or ``"board silent"`` and writes
the missing tail as a ``gap`` event after the last sample
(``lost=N,lost_s=T,cause=...``), up to the sample at which it stopped: the
planned stop, or the board's sample at the moment it gave up, estimated from
the host clock.

The output path is checked before the port is opened and the disk's free
space as soon as the board's header gives the sample rate, both before the
trigger: a machine's run is never lost to a path that cannot be written. A
write that fails part-way (disk full) stops the recording and raises
:class:`~imu_square.errors.OutputWriteError` saying how much the file kept.
"""

import collections
import math
import queue
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from acquisition.protocol import (
    REQUEST_HEADER,
    SEQ_MODULUS,
    DeviceHeader,
    Marker,
    Parser,
    SampleBlock,
)
from acquisition.reader import SerialSupervisor
from acquisition.stream import SampleStream
from acquisition.trigger import make_trigger
from imu_square.errors import AcquisitionError, ImuSquareError, OutputError, OutputWriteError
from imu_square.io.mcap import RecordingWriter, scan_mcap
from imu_square.io.output import check_free_space, check_output_path
from imu_square.io.recording import Event, SensorInfo
from imu_square.io.runlog import parse_detail, run_is_complete, run_problems
from imu_square.log import logger

HEADER_TIMEOUT_S = 5.0
HEADER_RETRY_S = 0.5
FLUSH_INTERVAL_S = 1.0
PRETRIGGER_S = 3.0
CHUNK_SIZE = 64 * 1024
MARKER_MARGIN_S = 2.0
SILENCE_S = 2.0  # host time without samples after which board time is extrapolated [s]
SILENCE_TIMEOUT_S = 10.0  # host time without samples after which the board is given up [s]
RATE_SPAN_S = 0.5  # host time of samples needed to measure the board's rate [s]
# Upper bound of the file's size per sample: the uncompressed chunks hold 20 B per sample
# at 1 kHz (24 B with a temperature; 14-18 B at 4 kHz) and zstd gives ~16 B on noisy data.
MAX_BYTES_PER_SAMPLE = 25
FILE_OVERHEAD_BYTES = 1e6  # attachments, metadata, summary and indexes, with room to spare


def _check_seconds(name, value, *, allow_none=False, allow_zero=False):
    """Refuse a time that is not a finite number of seconds above 0 (or 0 when allowed)."""
    if value is None and allow_none:
        return
    number = isinstance(value, int | float) and not isinstance(value, bool)
    if not (number and math.isfinite(value) and (value >= 0 if allow_zero else value > 0)):
        bound = ">= 0" if allow_zero else "> 0"
        raise AcquisitionError(f"{name} must be a number of seconds {bound}, got {value!r}")


def _identity(header):
    """What must not change within one recording: which board, its time base and scale."""
    return (header.model, header.serial, header.dt_ns, header.scale_m_s2_per_count)


def until_done_margin_s(program):
    """Extra time recorded after a program's nominal end: 2 s plus 5 %. [s]"""
    return 2.0 + 0.05 * program.duration_s


def parse_block_marker(text):
    """Split a marker text into an event kind, direction and block index.

    ``"block_start ccw 0"`` and ``"block_end cw 1"`` are block markers (the
    emulator sends them; a CNC can send them through the board's trigger
    input); any other text is a plain ``marker`` event.

    Parameters
    ----------
    text : str
        Marker text from the board.

    Returns
    -------
    tuple of (str, str, int, str)
        ``(kind, direction, block, detail)`` for :class:`Event`.
    """
    parts = text.split()
    if (
        len(parts) == 3
        and parts[0] in ("block_start", "block_end")
        and parts[1] in ("ccw", "cw")
        and parts[2].isdigit()
    ):
        return parts[0], parts[1], int(parts[2]), ""
    return "marker", "", -1, text


@dataclass
class RecorderStatus:
    """What the recorder has done so far; a snapshot goes to the progress callback.

    Attributes
    ----------
    state : str
        ``"waiting for header"``, ``"waiting for trigger"``, ``"recording"`` or
        ``"stopped"``.
    samples_written : int
        Samples in the file.
    lost : int
        Samples missing from the file between its first and last sample.
    gaps : int
        Gap events written.
    crc_errors : int
        Frames or lines rejected by the parser since the trigger.
    resyncs : int
        Times the parser found its framing again since the trigger.
    reconnects : int
        Times the port was reopened since the trigger.
    stale_blocks : int
        Blocks dropped because their sequence number did not move forward.
    recorded_s : float
        Board time from the trigger to the newest sample. [s]
    expected_s : float
        Board time from the trigger to the stop condition; the program's
        duration when open-ended; NaN before the trigger. [s]
    rate_hz : float
        Samples per second of host time, measured over the run. [Hz]
    elapsed_s : float
        Host time since the recorder started. [s]
    stop_reason : str
        ``"duration"`` or ``"done"`` (as planned), ``"interrupted"``, ``"port lost"``
        (it stayed lost), ``"board silent"`` (no samples), ``"board restarted"``,
        ``"error"``, ``"output error"`` (writing failed), or ``""`` while running.
    lost_at_end : int
        Samples missing after the last one received, up to where the recorder
        stopped, when the board went away (included in ``lost``).
    """

    state: str = "waiting for header"
    samples_written: int = 0
    lost: int = 0
    gaps: int = 0
    crc_errors: int = 0
    resyncs: int = 0
    reconnects: int = 0
    stale_blocks: int = 0
    recorded_s: float = 0.0
    expected_s: float = math.nan
    rate_hz: float = math.nan
    elapsed_s: float = 0.0
    stop_reason: str = ""
    lost_at_end: int = 0
    header: DeviceHeader | None = field(default=None, repr=False)

    @property
    def complete(self):
        """True for a run that stopped as planned with nothing lost, rejected or reconnected."""
        return run_is_complete(self.stop_reason, self.lost, self.crc_errors, self.reconnects)

    @property
    def problems(self):
        """Why the run is incomplete, one phrase per reason (empty when complete)."""
        dt_s = self.header.dt_ns * 1e-9 if self.header is not None else math.nan
        return run_problems(
            self.stop_reason,
            self.lost,
            self.crc_errors,
            self.reconnects,
            self.lost_at_end,
            self.lost_at_end * dt_s,
            self.stop_reason,
        )


class Recorder:
    """Records one test from a serial board into an MCAP file.

    Parameters
    ----------
    path : str or Path
        Output ``.mcap`` file.
    port : str
        Serial port, by a stable name (``/dev/serial/by-id/...``, a pty
        symlink) or a pyserial URL.
    baudrate : int
        Line speed. [bit/s]
    program : TestProgram, optional
        Program the machine runs; needed for ``until_done``.
    trigger : {"immediate", "motion", "marker"}
        When the recording starts.
    duration_s : float, optional
        Stop this long after the trigger, in board time. [s]
    until_done : bool
        Stop a margin after the last ``block_end`` marker, or after the
        program's nominal duration plus a margin from the trigger.
    machine_id : str
        Which machine the test ran on.
    mode : {None, "binary", "line"}
        Wire mode; None detects it from the first header.
    pretrigger_s : float
        Data kept from before the trigger. [s]
    progress : callable, optional
        Called with a :class:`RecorderStatus` about every ``progress_interval_s``.
    progress_interval_s : float
        Host time between progress calls. [s]
    header_timeout_s : float
        Give up if no header arrives within this host time after opening. [s]
    silence_timeout_s : float
        Give up on a board that sends no sample for this host time: the port
        stayed lost or the board hung. Longer than any unplugging the run
        should ride through. [s]
    overwrite : bool
        Replace an existing file at ``path`` (refused otherwise).

    Raises
    ------
    AcquisitionError
        On an option out of range, naming the option.
    """

    def __init__(
        self,
        path,
        port,
        *,
        baudrate=921600,
        program=None,
        trigger="immediate",
        duration_s=None,
        until_done=False,
        machine_id="",
        mode=None,
        pretrigger_s=PRETRIGGER_S,
        progress=None,
        progress_interval_s=0.5,
        header_timeout_s=HEADER_TIMEOUT_S,
        silence_timeout_s=SILENCE_TIMEOUT_S,
        overwrite=False,
    ):
        if until_done and program is None:
            raise AcquisitionError("until_done needs the test program (--program)")
        if isinstance(baudrate, bool) or not isinstance(baudrate, int) or baudrate <= 0:
            raise AcquisitionError(
                f"baud rate (--baud) must be a whole number > 0, got {baudrate!r}"
            )
        _check_seconds("duration (--duration)", duration_s, allow_none=True)
        _check_seconds("header timeout (--header-timeout)", header_timeout_s)
        _check_seconds("silence timeout (--silence-timeout)", silence_timeout_s)
        _check_seconds("pre-trigger time (--pretrigger)", pretrigger_s, allow_zero=True)
        self.path = path
        self.port = port
        self.baudrate = baudrate
        self.program = program
        self.trigger_kind = trigger
        self.duration_s = duration_s
        self.until_done = until_done
        self.machine_id = machine_id
        self.mode = mode
        self.pretrigger_s = pretrigger_s
        self.progress = progress
        self.progress_interval_s = progress_interval_s
        self.header_timeout_s = header_timeout_s
        self.silence_timeout_s = silence_timeout_s
        self.overwrite = overwrite
        self.status = RecorderStatus()
        self._stop = threading.Event()
        self._queue = queue.Queue()
        self._supervisor = SerialSupervisor(port, baudrate, self._queue)

    def stop(self):
        """Ask the recorder to finish; safe from a signal handler or another thread."""
        self._stop.set()

    # -- main loop -------------------------------------------------------------------------

    def run(self):
        """Record until a stop condition, :meth:`stop` or Ctrl-C; always finish the file.

        Returns
        -------
        RecorderStatus
            Final counts and why the recording stopped.

        Raises
        ------
        OutputError
            Before the port is opened, when the output cannot be written there
            (or exists, without ``overwrite``); before the trigger, when the
            disk cannot hold the recording.
        AcquisitionError
            When the port cannot be opened, or the board sends no header.
        OutputWriteError
            When writing failed part-way (disk full); the message says how
            much the file kept.
        """
        check_output_path(self.path, overwrite=self.overwrite)
        self._t0 = time.monotonic()
        self._parser = None
        self._stream = None
        self._writer = None
        self._trigger = None
        self._trigger_seq = None
        self._stop_seq = None
        self._stop_reason_pending = ""
        self._pending = collections.deque()  # (seq, "samples" | "event", payload)
        self._parser_events = []
        self._reconnect_detail = None
        self._down_since = None
        self._connects = 0
        self._first_data = None
        self._last_data = None
        self._samples_received = 0
        self._seq_first = None
        self._last_written = None
        self._t_start_ns = None
        self._alive = None  # [(host s, seq) of the first, of the last samples received]
        self._silent_since = None  # host time of the last sample (or the first header) [s]
        self._tail = None  # (end seq, cause) of the missing tail when the board went away
        self._header_seen = False  # a header from our board arrived on this connection
        self._output_failure = None
        self._supervisor.start()
        try:
            self._loop()
        except KeyboardInterrupt:
            self.status.stop_reason = "interrupted"
        except (AcquisitionError, OutputError):
            self.status.stop_reason = "error"
            raise
        finally:
            self._supervisor.stop()
            self._finish()
        if self._output_failure is not None:
            raise self._what_was_kept(self._output_failure)
        return self.status

    def _loop(self):
        next_flush = next_progress = next_request = time.monotonic()
        while not self.status.stop_reason:
            now = time.monotonic()
            self.status.elapsed_s = now - self._t0
            if self._stop.is_set():
                self.status.stop_reason = "interrupted"
                return
            if self.status.header is None:
                if now - self._t0 > self.header_timeout_s:
                    raise AcquisitionError(
                        f"no header from the board on {self.port!r} within "
                        f"{self.header_timeout_s:g} s: is it an imu-square board, and is "
                        f"--baud {self.baudrate} right?"
                    )
                if now >= next_request:
                    self._supervisor.write(REQUEST_HEADER)
                    next_request = now + HEADER_RETRY_S
            if self._writer is not None and now >= next_flush:
                self._output(self._writer.flush)
                next_flush = now + FLUSH_INTERVAL_S
            if self.progress is not None and now >= next_progress:
                self.progress(self.status)
                next_progress = now + self.progress_interval_s
            self._check_silence(now)
            try:
                kind, payload, host_ns = self._queue.get(timeout=0.1)
            except queue.Empty:
                continue
            if self.status.stop_reason:
                return
            if kind == "data":
                self._on_data(payload, host_ns)
            elif kind == "connect":
                self._on_connect(host_ns)
            elif self._down_since is None:
                self._down_since = host_ns

    # -- link and parser -------------------------------------------------------------------

    def _on_connect(self, host_ns):
        self._header_seen = False
        header = self.status.header
        self._parser = Parser(self.mode or (header.mode if header is not None else None))
        self._supervisor.write(REQUEST_HEADER)
        if self._connects:
            down_ns = host_ns - (self._down_since if self._down_since is not None else host_ns)
            self._reconnect_detail = f"down_s={down_ns * 1e-9:.3f}"
            self._down_since = None
        self._connects += 1

    def _on_data(self, data, host_ns):
        if self._first_data is None:
            self._first_data = host_ns
        self._last_data = host_ns
        stats = self._parser.stats
        errors, resyncs = stats.errors, stats.resyncs
        samples = stats.samples_ok
        messages = self._parser.feed(data)
        if stats.errors > errors:
            self._parser_events.append(("crc_error", f"count={stats.errors - errors}"))
        if self._trigger_seq is not None:
            self.status.resyncs += stats.resyncs - resyncs
        run = []  # consecutive sample blocks, handled as one
        for message in messages:
            if self.status.stop_reason:
                return
            if isinstance(message, SampleBlock):
                if run and (run[-1].seq0 + run[-1].n_samples) % SEQ_MODULUS != message.seq0:
                    self._on_samples(run)
                    run = []
                run.append(message)
                continue
            if run:
                self._on_samples(run)
                run = []
            if isinstance(message, Marker):
                self._on_marker(message)
            else:
                self._on_header(message)
        if run and not self.status.stop_reason:
            self._on_samples(run)
        if stats.samples_ok > samples and self._header_seen:
            self._note_samples(host_ns * 1e-9)

    def _note_samples(self, host_s):
        """Samples arrived at ``host_s``: the board is alive, and its rate can be measured."""
        seq = self._stream.last_seq
        if seq is None:
            return
        if self._alive is None:
            self._alive = [(host_s, seq), (host_s, seq)]
        self._alive[1] = (host_s, seq)
        self._silent_since = host_s

    def _on_header(self, header):
        old = self.status.header
        if old is None:
            self._silent_since = time.monotonic()
            self._check_space(header)
            self.status.header = header
            self.status.state = "waiting for trigger"
            self._stream = SampleStream(header.scale_m_s2_per_count)
            self._trigger = make_trigger(
                self.trigger_kind, header.dt_ns * 1e-9, header.scale_m_s2_per_count
            )
            logger.info(
                "board %s %s (firmware %s): %g Hz, %s mode",
                header.model,
                header.serial,
                header.firmware,
                header.sample_rate_hz,
                header.mode,
            )
        elif _identity(old) != _identity(header):
            logger.warning(
                "the board on %s is not the one the recording started with (model, serial, "
                "dt_ns, scale: %s -> %s): a reused port name, or the board was reconfigured; "
                "the recording stops here",
                self.port,
                _identity(old),
                _identity(header),
            )
            self._board_gone(self._board_at(time.monotonic() - self._silent_since), "board changed")
            return
        self._header_seen = True

    def _on_samples(self, blocks):
        if not self._header_seen:
            return  # before a header on this connection: which board, at what scale?
        if len(blocks) == 1:
            counts = blocks[0].counts
            temperature = np.full(blocks[0].n_samples, blocks[0].temperature_c)
        else:
            counts = np.concatenate([b.counts for b in blocks])
            temperature = np.repeat(
                [b.temperature_c for b in blocks], [b.n_samples for b in blocks]
            )
        back_to = self._stream.unwrap(blocks[0].seq0)
        seq, accel, temperature, lost = self._stream.push(blocks[0].seq0, counts, temperature)
        self.status.stale_blocks = self._stream.stale
        if seq is None:
            if back_to < self._stream.last_seq - self._samples(1.0):
                self._board_restarted(back_to)
            return
        s0 = int(seq[0])
        if lost:
            self._queue_event(s0, "gap", detail=self._gap_detail(lost))
        if self._reconnect_detail is not None:
            self._queue_event(s0, "reconnect", detail=self._reconnect_detail)
            self._reconnect_detail = None
        for kind, detail in self._parser_events:
            self._queue_event(s0, kind, detail=detail)
        self._parser_events = []
        self._pending.append((s0, "samples", (seq, accel, temperature, time.time_ns())))
        self._samples_received += seq.size
        if self._last_data > self._first_data:
            span_s = (self._last_data - self._first_data) * 1e-9
            self.status.rate_hz = self._samples_received / span_s
        if self._trigger_seq is None:
            fired = self._trigger.update(seq, accel)
            if fired is None:
                self._trim_pretrigger()
                return
            self._start(fired)
        self._drain()

    def _board_restarted(self, back_to):
        """The counter went back by more than a second: the board restarted; end the file."""
        last = self._stream.last_seq
        logger.warning(
            "the board's sequence counter went back from %d to %d: it restarted, and its "
            "clock with it; the recording ends here",
            last,
            back_to,
        )
        if self._writer is not None:
            detail = f"board restarted: sequence went back from {last} to {back_to}"
            self._write_event(max(last, self._seq_first), "marker", "", -1, detail)
        self.status.stop_reason = "board restarted"

    def _on_marker(self, marker):
        if not self._header_seen or self._stream.last_seq is None:
            return
        seq = self._stream.unwrap(marker.seq)
        kind, direction, block, detail = parse_block_marker(marker.text)
        self._queue_event(seq, kind, direction, block, detail)
        if self._trigger_seq is None:
            fired = self._trigger.on_marker(seq, marker.text)
            if fired is None:
                return
            self._start(fired)
        if self.until_done and kind == "block_end" and block == self.program.n_blocks - 1:
            self._set_stop(seq + self._samples(MARKER_MARGIN_S), "done", replace=True)
        self._drain()

    def _queue_event(self, seq, kind, direction="", block=-1, detail=""):
        self._pending.append((seq, "event", (kind, direction, block, detail)))

    # -- trigger, writing and stopping -----------------------------------------------------

    def _samples(self, seconds):
        return round(seconds * 1e9 / self.status.header.dt_ns)

    def _trim_pretrigger(self):
        # Keep the pre-trigger time plus what the motion trigger needs to decide.
        keep_from = self._stream.last_seq - self._samples(self.pretrigger_s + 2.0)
        while self._pending and self._pending[0][0] < keep_from:
            self._pending.popleft()

    def _start(self, trigger_seq, fired=True):
        """Open the file at the trigger, keeping ``pretrigger_s`` of what came before.

        ``fired=False``: the recorder stopped while waiting for the trigger, and
        the file keeps the buffer up to ``trigger_seq``, with no stop condition.
        """
        dt = self.status.header.dt_ns
        self._trigger_seq = trigger_seq
        self.status.state = "recording"
        first = trigger_seq - self._samples(self.pretrigger_s)
        blocks = [p for s, k, p in self._pending if k == "samples" and p[0][-1] >= first]
        if blocks:
            seq, _, _, received_ns = blocks[0]
            self._seq_first = max(first, int(seq[0]))
            self._t_start_ns = received_ns - (int(seq[-1]) - self._seq_first) * dt
        else:  # a marker announced the start before its samples arrived
            self._seq_first = trigger_seq
            self._t_start_ns = time.time_ns()
        detail = f"trigger={self.trigger_kind}" + ("" if fired else ",fired=no")
        self._queue_event(trigger_seq, "run_start", detail=detail)
        self._pending = collections.deque(
            sorted(
                (item for item in self._pending if self._in_file(item)), key=lambda item: item[0]
            )
        )
        self._open_writer()
        if not fired:
            return
        if self.duration_s is not None:
            self._set_stop(trigger_seq + self._samples(self.duration_s), "duration")
        elif self.until_done:
            expected = self.program.duration_s + until_done_margin_s(self.program)
            self._set_stop(trigger_seq + self._samples(expected), "done")
        elif self.program is not None:  # open-ended: show progress against the program
            self.status.expected_s = self.program.duration_s
        logger.info("trigger (%s) at sequence number %d", self.trigger_kind, trigger_seq)

    def _in_file(self, item):
        seq, kind, payload = item
        if kind == "samples":
            return payload[0][-1] >= self._seq_first
        if payload[0] in ("gap", "crc_error", "reconnect"):
            return seq > self._seq_first  # what happened before the file's first sample
        return seq >= self._seq_first

    def _set_stop(self, stop_seq, reason, replace=False):
        if replace or self._stop_seq is None or stop_seq < self._stop_seq:
            self._stop_seq = stop_seq
            self._stop_reason_pending = reason
            dt_s = self.status.header.dt_ns * 1e-9
            self.status.expected_s = (stop_seq - self._trigger_seq) * dt_s

    def _time_ns(self, seq):
        return self._t_start_ns + (seq - self._seq_first) * self.status.header.dt_ns

    def _drain(self):
        """Write everything pending up to the stop condition."""
        if self.status.stop_reason in ("duration", "done"):
            self._pending.clear()
            return
        limit = self._stop_seq if self._stop_seq is not None else np.iinfo(np.int64).max
        with_temperature = self.status.header.has_temperature
        while self._pending and self._output_failure is None:
            seq0, kind, payload = self._pending.popleft()
            if seq0 >= limit:
                self._reached_stop()
                return
            if kind == "event":
                self._write_event(seq0, *payload)
                continue
            seq, accel, temperature, _ = payload
            keep = (seq >= self._seq_first) & (seq < limit)
            if not keep.all():
                seq, accel, temperature = seq[keep], accel[keep], temperature[keep]
            temperature = temperature if with_temperature else None
            if seq.size and self._output(
                self._writer.write_samples, seq, self._time_ns(seq), accel, temperature
            ):
                self._last_written = int(seq[-1])
                self.status.samples_written += seq.size
                self.status.recorded_s = (
                    (self._last_written + 1 - self._trigger_seq) * self.status.header.dt_ns * 1e-9
                )
            if self._last_written is not None and self._last_written >= limit - 1:
                self._reached_stop()
                return

    def _reached_stop(self):
        self.status.stop_reason = self._stop_reason_pending
        self._pending.clear()

    def _write_event(self, seq, kind, direction, block, detail):
        if not self._output(
            self._writer.write_event, Event(self._time_ns(seq), kind, direction, block, detail)
        ):
            return
        if kind == "gap":
            self.status.gaps += 1
            self.status.lost += int(parse_detail(detail)["lost"])
        elif kind == "crc_error":
            self.status.crc_errors += int(parse_detail(detail)["count"])
        elif kind == "reconnect":
            self.status.reconnects += 1

    def _gap_detail(self, lost):
        return f"lost={lost},lost_s={lost * self.status.header.dt_ns * 1e-9:.3f}"

    # -- a board that goes away ------------------------------------------------------------

    def _board_rate(self):
        """Board samples per host second: measured once samples span a while, else nominal.

        Measured from the end of the first read, which may hold a backlog; the
        nominal rate is the header's, right for any real board (an emulated one
        may run faster than real time).
        """
        if self._alive is not None:
            (t0, s0), (t1, s1) = self._alive
            if t1 - t0 >= RATE_SPAN_S:
                return (s1 - s0) / (t1 - t0)
        return self.status.header.sample_rate_hz

    def _check_silence(self, now):
        """Stop when the board is gone: silent past the planned stop, or past the time-out.

        While silent for more than ``SILENCE_S`` the board's sample counter is
        estimated from the host clock; once it passes the planned stop, nothing
        more can come in time. After ``silence_timeout_s`` the board is given up
        at once. Either way what is missing up to there becomes the tail gap.
        """
        if self._silent_since is None or self.status.stop_reason or not self._queue.empty():
            return
        silent_s = now - self._silent_since
        if silent_s <= min(SILENCE_S, self.silence_timeout_s):
            return
        board_at = self._board_at(silent_s)
        at_stop = None not in (board_at, self._stop_seq) and board_at >= self._stop_seq
        if silent_s <= self.silence_timeout_s and not at_stop:
            return
        cause = "port lost" if self._down_since is not None else "board silent"
        logger.warning(
            "no sample from the board on %s for %.1f s (%s): the recording stops, and the "
            "missing time is recorded as a gap; the run is incomplete",
            self.port,
            silent_s,
            "the port stayed lost" if cause == "port lost" else "the port is open but silent",
        )
        self._board_gone(board_at, cause)

    def _board_at(self, silent_s):
        """Next sample the board would send now, from the host clock; None before any."""
        last = self._stream.last_seq if self._stream is not None else None
        if last is None:
            return None
        return last + 1 + round(silent_s * self._board_rate())

    def _board_gone(self, board_at, cause):
        """Stop: what is missing up to ``board_at`` (or the planned stop) is the tail gap."""
        if board_at is not None and self._stop_seq is not None:
            board_at = min(board_at, self._stop_seq)
        self._tail = None if board_at is None else (board_at, cause)
        self.status.stop_reason = cause

    def _write_tail(self):
        """The gap from the last sample written to where the recorder stopped."""
        end, cause = self._tail
        first = self._last_written + 1 if self._last_written is not None else self._seq_first
        lost = end - first
        if lost > 0:
            self._write_event(first, "gap", "", -1, f"{self._gap_detail(lost)},cause={cause}")
            self.status.lost_at_end = lost

    # -- the output file -------------------------------------------------------------------

    def _check_space(self, header):
        """Refuse, before the trigger, a disk that cannot hold the planned recording."""
        if self.duration_s is not None:
            span_s = self.duration_s
        elif self.program is not None:
            span_s = self.program.duration_s
            if self.until_done:
                span_s += until_done_margin_s(self.program)
        else:
            return  # open-ended, no program: nothing to go by
        span_s += self.pretrigger_s
        needed = span_s * header.sample_rate_hz * MAX_BYTES_PER_SAMPLE + FILE_OVERHEAD_BYTES
        check_free_space(self.path, needed, f"{span_s:.0f} s at {header.sample_rate_hz:g} Hz")

    def _output(self, method, *args):
        """Call a writer method; on a failure keep it, stop recording and return False."""
        if self._output_failure is not None:
            return False
        try:
            method(*args)
        except OutputError as exc:
            self._output_failure = exc
            self.status.stop_reason = "output error"
            return False
        return True

    def _what_was_kept(self, failure):
        """The output failure, with what the file kept when writing had started."""
        if not isinstance(failure, OutputWriteError):
            return failure
        try:
            kept = scan_mcap(self.path).report
        except ImuSquareError:
            return OutputWriteError(f"{failure}; nothing readable was kept")
        return OutputWriteError(
            f"{failure}; the file keeps {kept.samples} samples ({kept.duration_s:.3f} s) from "
            f"the chunks flushed before: 'imu-square recover {self.path} -o FIXED.mcap' "
            f"rewrites them as a whole file"
        )

    def _open_writer(self):
        h = self.status.header
        sensor = SensorInfo(
            model=h.model,
            serial=h.serial,
            noise_density_m_s2_rthz=h.noise_density_m_s2_rthz,
            range_m_s2=h.range_m_s2,
            resolution_m_s2=h.scale_m_s2_per_count,
        )
        metadata = {
            "producer": "imu-square record",
            "port": str(self.port),
            "baudrate": str(self.baudrate),
            "wire_mode": h.mode,
            "firmware": h.firmware,
            "sample_rate_hz": repr(h.sample_rate_hz),
            "scale_m_s2_per_count": repr(h.scale_m_s2_per_count),
            "trigger": self.trigger_kind,
            "trigger_seq": str(self._trigger_seq),
            "time_base": "board sequence number: t_start_ns + (seq - seq_first) * dt_ns",
            "t_start_source": "host UTC clock at the arrival of the first block",
        }
        self._output(self._create_writer, sensor, metadata)

    def _create_writer(self, sensor, metadata):
        h = self.status.header
        self._writer = RecordingWriter(
            self.path,
            dt_ns=h.dt_ns,
            program=self.program,
            sensor=sensor,
            machine_id=self.machine_id,
            metadata=metadata,
            chunk_size=CHUNK_SIZE,
            fsync=True,
        )

    def _finish(self):
        if (
            self._writer is None
            and self.status.stop_reason not in ("error", "output error")
            and self._stream is not None
            and self._stream.last_seq is not None
        ):
            self._start(self._stream.last_seq, fired=False)  # stopped while waiting: keep it
        self.status.state = "stopped"
        if self._writer is None:
            return
        self._drain()
        if self._tail is not None:
            self._write_tail()
        s = self.status
        end = self._last_written if self._last_written is not None else self._seq_first
        end += s.lost_at_end  # where the recorder stopped: the end of a missing tail
        detail = (
            f"stop={s.stop_reason or 'interrupted'},samples={s.samples_written},lost={s.lost},"
            f"crc_errors={s.crc_errors},resyncs={s.resyncs},reconnects={s.reconnects},"
            f"stale_blocks={s.stale_blocks},host_rate_hz={s.rate_hz:.3f}"
        )
        self._output(self._writer.write_event, Event(self._time_ns(end), "run_end", detail=detail))
        self._output(self._writer.close)
        self._writer = None
