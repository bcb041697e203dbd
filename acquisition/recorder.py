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
number of samples lost.
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
from imu_square.errors import AcquisitionError
from imu_square.io.mcap import RecordingWriter
from imu_square.io.recording import Event, SensorInfo
from imu_square.log import logger

HEADER_TIMEOUT_S = 5.0
HEADER_RETRY_S = 0.5
FLUSH_INTERVAL_S = 1.0
PRETRIGGER_S = 3.0
CHUNK_SIZE = 64 * 1024
MARKER_MARGIN_S = 2.0
SILENCE_S = 2.0  # host time without data after which board time is extrapolated [s]


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
        ``"duration"``, ``"done"``, ``"interrupted"``, ``"board restarted"``,
        ``"error"``, or ``""`` while running.
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
    header: DeviceHeader | None = field(default=None, repr=False)

    @property
    def complete(self):
        """True for a run that stopped as planned with nothing lost, rejected or reconnected."""
        return (
            self.stop_reason in ("duration", "done")
            and self.lost == 0
            and self.crc_errors == 0
            and self.reconnects == 0
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
    ):
        if until_done and program is None:
            raise AcquisitionError("until_done needs the test program (--program)")
        if duration_s is not None and not duration_s > 0:
            raise AcquisitionError(f"duration_s must be > 0, got {duration_s!r}")
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
        AcquisitionError
            When the port cannot be opened, the board sends no header, or its
            header changes mid-run (the file is finished first).
        """
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
        self._supervisor.start()
        try:
            self._loop()
        except KeyboardInterrupt:
            self.status.stop_reason = "interrupted"
        except AcquisitionError:
            self.status.stop_reason = "error"
            raise
        finally:
            self._supervisor.stop()
            self._finish()
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
                self._writer.flush()
                next_flush = now + FLUSH_INTERVAL_S
            if self.progress is not None and now >= next_progress:
                self.progress(self.status)
                next_progress = now + self.progress_interval_s
            self._check_stop_while_silent()
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
        messages = self._parser.feed(data)
        if stats.errors > errors:
            self._parser_events.append(("crc_error", f"count={stats.errors - errors}"))
        if self._trigger_seq is not None:
            self.status.resyncs += stats.resyncs - resyncs
        run = []  # consecutive sample blocks, handled as one
        for message in messages:
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
        if run:
            self._on_samples(run)

    def _on_header(self, header):
        old = self.status.header
        if old is None:
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
        elif (old.dt_ns, old.scale_m_s2_per_count) != (header.dt_ns, header.scale_m_s2_per_count):
            raise AcquisitionError(
                f"the board on {self.port!r} changed its header mid-run (dt_ns {old.dt_ns} -> "
                f"{header.dt_ns}, scale {old.scale_m_s2_per_count!r} -> "
                f"{header.scale_m_s2_per_count!r}); the file ends there"
            )

    def _on_samples(self, blocks):
        if self._stream is None:
            return  # before the first header the scale is unknown
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
            self._queue_event(s0, "gap", detail=f"lost={lost}")
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
        if self._stream is None or self._stream.last_seq is None:
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

    def _start(self, trigger_seq):
        """Open the file at the trigger, keeping ``pretrigger_s`` of what came before."""
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
        self._queue_event(trigger_seq, "run_start", detail=f"trigger={self.trigger_kind}")
        self._pending = collections.deque(
            sorted(
                (item for item in self._pending if self._in_file(item)), key=lambda item: item[0]
            )
        )
        self._open_writer()
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
        while self._pending:
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
            if seq.size:
                self._writer.write_samples(
                    seq, self._time_ns(seq), accel, temperature if with_temperature else None
                )
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
        if kind == "gap":
            self.status.gaps += 1
            self.status.lost += int(detail.partition("=")[2])
        elif kind == "crc_error":
            self.status.crc_errors += int(detail.partition("=")[2])
        elif kind == "reconnect":
            self.status.reconnects += 1
        self._writer.write_event(Event(self._time_ns(seq), kind, direction, block, detail))

    def _check_stop_while_silent(self):
        """Stop on time when the board falls silent, estimating its clock from the host's."""
        if (
            self._stop_seq is None
            or self._last_data is None
            or not self.status.rate_hz > 0
            or not self._queue.empty()
        ):
            return
        silent_s = (time.monotonic_ns() - self._last_data) * 1e-9
        if silent_s > SILENCE_S and self._stream.last_seq + silent_s * self.status.rate_hz >= (
            self._stop_seq
        ):
            self._reached_stop()

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
        self.status.state = "stopped"
        if self._writer is None and self._stream is not None and self._stream.last_seq is not None:
            self._start(self._stream.last_seq)  # stopped while waiting: keep the buffer
        if self._writer is None:
            return
        self._drain()
        s = self.status
        end = self._last_written if self._last_written is not None else self._seq_first
        detail = (
            f"stop={s.stop_reason or 'interrupted'},samples={s.samples_written},lost={s.lost},"
            f"crc_errors={s.crc_errors},resyncs={s.resyncs},reconnects={s.reconnects},"
            f"stale_blocks={s.stale_blocks},host_rate_hz={s.rate_hz:.3f}"
        )
        self._writer.write_event(Event(self._time_ns(end), "run_end", detail=detail))
        self._writer.close()
        self._writer = None
