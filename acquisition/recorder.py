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
number of samples lost (``lost=N,lost_s=T``). The link's health (reconnects,
silence, the host rate) is kept by a :class:`~acquisition.link.LinkHealth`;
what the recorder reports, with its :class:`~acquisition.status.RecorderState`,
by a :class:`~acquisition.status.RecorderStatus`.

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
import queue
import threading
import time

import numpy as np

from acquisition.link import LinkHealth
from acquisition.protocol import (
    REQUEST_HEADER,
    SEQ_MODULUS,
    Marker,
    Parser,
    SampleBlock,
)
from acquisition.reader import SerialSupervisor
from acquisition.status import RecorderState, RecorderStatus
from acquisition.stream import SampleStream
from acquisition.trigger import make_trigger
from imu_square.errors import AcquisitionError, ImuSquareError, OutputError, OutputWriteError
from imu_square.io.mcap import RecordingWriter, scan_mcap
from imu_square.io.output import check_free_space, check_output_path
from imu_square.io.recording import Event, SensorInfo
from imu_square.io.runlog import parse_detail
from imu_square.log import logger
from imu_square.validation import check_number

HEADER_TIMEOUT_S = 5.0
HEADER_RETRY_S = 0.5
FLUSH_INTERVAL_S = 1.0
PRETRIGGER_S = 3.0
CHUNK_SIZE = 64 * 1024
MARKER_MARGIN_S = 2.0
SILENCE_TIMEOUT_S = 10.0  # host time without samples after which the board is given up [s]
# Upper bound of the file's size per sample: the uncompressed chunks hold 20 B per sample
# at 1 kHz (24 B with a temperature; 14-18 B at 4 kHz) and zstd gives ~16 B on noisy data.
MAX_BYTES_PER_SAMPLE = 25
FILE_OVERHEAD_BYTES = 1e6  # attachments, metadata, summary and indexes, with room to spare


def _check_seconds(name, value, *, allow_none=False, allow_zero=False):
    """Refuse a time that is not a finite number of seconds above 0 (or 0 when allowed)."""
    if value is None and allow_none:
        return
    seconds = f"a number of seconds {'>= 0' if allow_zero else '> 0'}"
    check_number(
        name,
        value,
        0.0,
        lo_open=not allow_zero,
        kind=seconds,
        allowed=seconds,
        error=AcquisitionError,
    )


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
        self._link = LinkHealth(self.port, self.silence_timeout_s)
        self._seq_first = None
        self._last_written = None
        self._t_start_ns = None
        self._tail = None  # (end seq, cause) of the missing tail when the board went away
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
            else:
                self._link.disconnected(host_ns)

    # -- link and parser -------------------------------------------------------------------

    def _on_connect(self, host_ns):
        self._link.connected(host_ns)
        header = self.status.header
        self._parser = Parser(self.mode or (header.mode if header is not None else None))
        self._supervisor.write(REQUEST_HEADER)

    def _on_data(self, data, host_ns):
        self._link.data(host_ns)
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
        if stats.samples_ok > samples and self._link.header_seen:
            self._link.samples_arrived(host_ns * 1e-9, self._stream.last_seq)

    def _on_header(self, header):
        old = self.status.header
        if old is None:
            self._link.first_header(time.monotonic(), header.sample_rate_hz)
            self._check_space(header)
            self.status.header = header
            self.status.enter(RecorderState.WAITING_FOR_TRIGGER)
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
            self._board_gone(
                self._link.board_at(time.monotonic(), self._stream.last_seq), "board changed"
            )
            return
        self._link.header_seen = True

    def _on_samples(self, blocks):
        if not self._link.header_seen:
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
        reconnect = self._link.take_reconnect()
        if reconnect is not None:
            self._queue_event(s0, "reconnect", detail=reconnect)
        for kind, detail in self._parser_events:
            self._queue_event(s0, kind, detail=detail)
        self._parser_events = []
        self._pending.append((s0, "samples", (seq, accel, temperature, time.time_ns())))
        self.status.rate_hz = self._link.count_samples(seq.size)
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
        if not self._link.header_seen or self._stream.last_seq is None:
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
        self.status.enter(RecorderState.RECORDING)
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

    def _check_silence(self, now):
        """Stop when the board is gone; what is missing up to there becomes the tail gap."""
        if self.status.stop_reason or not self._queue.empty():
            return
        last_seq = self._stream.last_seq if self._stream is not None else None
        gone = self._link.gone(now, last_seq, self._stop_seq)
        if gone is not None:
            self._board_gone(*gone)

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
        self.status.enter(RecorderState.STOPPED)
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
