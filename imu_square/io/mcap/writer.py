"""Write a recording to MCAP, streaming, while it is being acquired.

Chunks are zstd-compressed and about 128 KiB, so a file cut by a crash or a
pulled cable loses at most a few seconds. What goes on which topic is in
:mod:`imu_square.io.mcap.topics`.
"""

import json
import math
import os
from contextlib import contextmanager
from dataclasses import asdict
from pathlib import Path

import numpy as np
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, Writer

import imu_square
from imu_square.errors import OutputError, OutputWriteError, RecordingError
from imu_square.io.cdr import (
    ACCEL_BATCH_SCHEMA,
    ACCEL_BATCH_SCHEMA_NAME,
    VECTOR3_STAMPED_SCHEMA,
    VECTOR3_STAMPED_SCHEMA_NAME,
    encode_accel_batch,
    encode_vector3_stamped,
)
from imu_square.io.mcap.topics import (
    ACCEL_TOPIC,
    EVENT_SCHEMA,
    EVENTS_TOPIC,
    PREVIEW_TOPIC,
    PROGRAM_ATTACHMENT,
)
from imu_square.io.recording import SensorInfo

BATCH_S = 0.1  # duration of one AccelBatch message [s]
PREVIEW_RATE_HZ = 100.0  # upper bound of the preview rate [Hz]
MAX_BATCH_S = 1.0

_INT32_MAX = 2**31 - 1
_U32 = 2**32


def batch_layout(dt_ns):
    """Samples per preview message and per AccelBatch message for a sample spacing.

    Parameters
    ----------
    dt_ns : int
        Nominal sample spacing. [ns]

    Returns
    -------
    per_preview : int
        Samples averaged into one preview message, so the preview runs at
        most at :data:`PREVIEW_RATE_HZ`.
    per_batch : int
        Samples per AccelBatch, a multiple of ``per_preview`` close to
        :data:`BATCH_S` and never longer than :data:`MAX_BATCH_S`.
    """
    per_preview = max(1, math.ceil(1e9 / PREVIEW_RATE_HZ / dt_ns))
    groups = max(1, round(BATCH_S * 1e9 / (per_preview * dt_ns)))
    while groups > 1 and groups * per_preview * dt_ns > MAX_BATCH_S * 1e9:
        groups -= 1
    return per_preview, groups * per_preview


class RecordingWriter:
    """Write a recording to MCAP while it is being acquired.

    Samples are buffered into batches of about 0.1 s; a jump in ``seq``
    closes the batch. Use as a context manager, or call :meth:`close`.

    Parameters
    ----------
    path_or_stream : str, Path or binary file object
        Destination; a path is created (truncated) and closed by the writer,
        a stream must be seekable-for-``tell`` and is left open.
    dt_ns : int
        Nominal sample spacing. [ns]
    program : TestProgram, optional
        The program the machine runs, stored as the ``program.toml`` attachment.
    sensor : SensorInfo
        Sensor identity and specifications.
    machine_id : str
        Machine the test runs on.
    metadata : dict of str to str, optional
        Anything else worth keeping; read back as ``Recording.metadata``.
    processing : list of str, optional
        Processing log; read back as ``Recording.processing``.
    chunk_size : int
        Uncompressed chunk size that closes a chunk. [bytes]
    fsync : bool
        Whether :meth:`flush` and :meth:`close` also fsync the file.

    Attributes
    ----------
    samples_written : int
        Samples given to :meth:`write_samples` so far.

    Raises
    ------
    OutputError
        When the file cannot be created.
    OutputWriteError
        From any method, when writing fails part-way (disk full, I/O error):
        the writer is then closed, and the file keeps what was written before
        (every complete chunk; :func:`~imu_square.io.mcap.reader.scan_mcap` reads it).
    """

    def __init__(
        self,
        path_or_stream,
        *,
        dt_ns,
        program=None,
        sensor=None,
        machine_id="",
        metadata=None,
        processing=None,
        chunk_size=128 * 1024,
        fsync=False,
    ):
        if isinstance(dt_ns, bool) or int(dt_ns) != dt_ns or not 0 < int(dt_ns) < _U32:
            raise RecordingError(f"dt_ns must be an integer in [1, 2**32), got {dt_ns!r}")
        self.dt_ns = int(dt_ns)
        self.per_preview, self.per_batch = batch_layout(self.dt_ns)
        self.samples_written = 0
        self._fsync = fsync
        self._closed = False
        self._owns = isinstance(path_or_stream, str | os.PathLike)
        self._name = str(path_or_stream) if self._owns else "<stream>"
        self._stream = _create(path_or_stream) if self._owns else path_or_stream
        self._pending = None  # (seq, time_ns, accel, temperature) not yet in a batch
        self._last = None  # (seq, time_ns) of the last sample received
        self._has_temperature = None
        self._writer = Writer(
            self._stream, chunk_size=int(chunk_size), compression=CompressionType.ZSTD
        )
        with self._writing():
            self._start(program, sensor, machine_id, metadata, processing)

    def _start(self, program, sensor, machine_id, metadata, processing):
        self._writer.start(
            profile="ros2", library=f"imu-square {imu_square.__version__}; {LIBRARY_IDENTIFIER}"
        )
        w = self._writer
        accel_schema = w.register_schema(
            ACCEL_BATCH_SCHEMA_NAME, SchemaEncoding.ROS2, ACCEL_BATCH_SCHEMA.encode()
        )
        preview_schema = w.register_schema(
            VECTOR3_STAMPED_SCHEMA_NAME, SchemaEncoding.ROS2, VECTOR3_STAMPED_SCHEMA.encode()
        )
        event_schema = w.register_schema(
            "imu_square.Event", SchemaEncoding.JSONSchema, json.dumps(EVENT_SCHEMA).encode()
        )
        self._accel_ch = w.register_channel(ACCEL_TOPIC, MessageEncoding.CDR, accel_schema)
        self._preview_ch = w.register_channel(PREVIEW_TOPIC, MessageEncoding.CDR, preview_schema)
        self._event_ch = w.register_channel(EVENTS_TOPIC, MessageEncoding.JSON, event_schema)
        if program is not None:
            w.add_attachment(
                create_time=0,
                log_time=0,
                name=PROGRAM_ATTACHMENT,
                media_type="application/toml",
                data=program.to_toml().encode(),
            )
        sensor = SensorInfo() if sensor is None else sensor
        w.add_metadata("sensor", {k: str(v) for k, v in asdict(sensor).items()})
        w.add_metadata("machine", {"machine_id": str(machine_id)})
        w.add_metadata(
            "software",
            {"name": "imu-square", "version": imu_square.__version__, "dt_ns": str(self.dt_ns)},
        )
        w.add_metadata(
            "recording",
            {
                "metadata": json.dumps(dict(metadata or {})),
                "processing": json.dumps(list(processing or [])),
            },
        )

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def write_samples(self, seq, time_ns, accel, temperature_c=None):
        """Add samples; they are written in batches of about 0.1 s.

        Parameters
        ----------
        seq : ndarray of int, shape (n,)
            Unwrapped sequence numbers, strictly increasing over all calls.
        time_ns : ndarray of int, shape (n,)
            Sample times, strictly increasing over all calls. [ns]
        accel : ndarray, shape (n, 3)
            Acceleration in the sensor frame, stored as float32. [m/s^2]
        temperature_c : ndarray, shape (n,), optional
            Sensor temperature, stored as float32; give it in every call or
            in none. [degC]
        """
        self._check_open()
        seq = np.asarray(seq, np.int64).reshape(-1)
        time_ns = np.asarray(time_ns, np.int64).reshape(-1)
        accel = np.asarray(accel, np.float32).reshape(-1, 3)
        n = seq.shape[0]
        if time_ns.shape != (n,) or accel.shape != (n, 3):
            raise RecordingError(
                f"write_samples: seq, time_ns and accel must hold the same number of samples, "
                f"got {seq.shape}, {time_ns.shape} and {accel.shape}"
            )
        if self._has_temperature is None:
            self._has_temperature = temperature_c is not None
        if (temperature_c is not None) != self._has_temperature:
            raise RecordingError(
                "write_samples: temperature_c must be given in every call or in none"
            )
        temp = None if temperature_c is None else np.asarray(temperature_c, np.float32)
        if temp is not None and temp.shape != (n,):
            raise RecordingError(f"write_samples: temperature_c must have shape ({n},)")
        if n == 0:
            return
        prev_seq, prev_t = self._last if self._last is not None else (seq[0] - 1, time_ns[0] - 1)
        if np.any(np.diff(seq, prepend=prev_seq) <= 0) or np.any(
            np.diff(time_ns, prepend=prev_t) <= 0
        ):
            raise RecordingError(
                "write_samples: seq and time_ns must increase strictly, also across calls"
            )
        with self._writing():
            if self._last is None:
                self._writer.add_metadata("sequence", {"first_seq": str(int(seq[0]))})
            self._last = (int(seq[-1]), int(time_ns[-1]))
            self.samples_written += n
            if self._pending is not None:
                p = self._pending
                seq = np.concatenate([p[0], seq])
                time_ns = np.concatenate([p[1], time_ns])
                accel = np.concatenate([p[2], accel])
                temp = None if temp is None else np.concatenate([p[3], temp])
            self._pending = self._write_batches(seq, time_ns, accel, temp, final=False)

    def _write_batches(self, seq, time_ns, accel, temp, final):
        """Write full batches; return the samples left over (or None)."""
        start, n = 0, seq.shape[0]
        while start < n:
            stop = min(n, start + self.per_batch)
            jumps = np.flatnonzero(np.diff(seq[start:stop]) != 1)
            if jumps.size:
                stop = start + int(jumps[0]) + 1
            offsets = time_ns[start:stop] - time_ns[start] - self.dt_ns * np.arange(stop - start)
            too_far = np.flatnonzero(np.abs(offsets) > _INT32_MAX)
            if too_far.size:
                stop = start + int(too_far[0])
                offsets = offsets[: stop - start]
            if stop == n and stop - start < self.per_batch and not final:
                break
            sl = slice(start, stop)
            self._write_batch(
                int(seq[start]),
                time_ns[sl],
                accel[sl],
                None if temp is None else temp[sl],
                offsets if offsets.any() else None,
            )
            start = stop
        if start == n:
            return None
        rest = slice(start, n)
        return seq[rest], time_ns[rest], accel[rest], None if temp is None else temp[rest]

    def _write_batch(self, seq0, time_ns, accel, temp, offsets):
        t0 = int(time_ns[0])
        data = encode_accel_batch(seq0, self.dt_ns, t0, accel, temp, offsets)
        log_time = max(t0, 0)
        self._writer.add_message(self._accel_ch, log_time, data, log_time, seq0 & 0xFFFFFFFF)
        # Preview: mean over consecutive groups of per_preview samples.
        m = self.per_preview
        n = time_ns.shape[0]
        edges = np.arange(0, n, m)
        sums = np.add.reduceat(accel.astype(np.float64), edges, axis=0)
        rel = np.add.reduceat(time_ns - t0, edges)
        sizes = np.diff(np.append(edges, n))
        stamps = t0 + rel // sizes
        for stamp, msg in zip(
            stamps.tolist(), encode_vector3_stamped(stamps, sums / sizes[:, None]), strict=True
        ):
            self._writer.add_message(self._preview_ch, max(stamp, 0), msg, max(stamp, 0))

    def write_event(self, event):
        """Write one event.

        Parameters
        ----------
        event : Event
            The event; its ``time_ns`` [ns] is on the samples' clock.
        """
        self._check_open()
        data = json.dumps(
            {
                "time_ns": int(event.time_ns),
                "kind": str(event.kind),
                "direction": str(event.direction),
                "block": int(event.block),
                "detail": str(event.detail),
            }
        ).encode()
        log_time = max(int(event.time_ns), 0)
        with self._writing():
            self._writer.add_message(self._event_ch, log_time, data, log_time)

    def flush(self):
        """Write the pending partial batch, close the current chunk, fsync if asked.

        After this returns, a copy of the file as it is on disk (as a crash
        would leave it) yields every sample written so far.
        """
        self._check_open()
        with self._writing():
            if self._pending is not None:
                self._pending = self._write_batches(*self._pending, final=True)
            self._writer.flush()
            self._sync()

    def close(self):
        """Finish the file (summary and indexes) and close it; idempotent."""
        if self._closed:
            return
        try:
            with self._writing():
                if self._pending is not None:
                    self._pending = self._write_batches(*self._pending, final=True)
                self._writer.finish()
                self._stream.flush()
                self._sync()
        finally:
            if not self._closed:  # not already closed by a write failure
                self._closed = True
                if self._owns:
                    self._stream.close()

    @contextmanager
    def _writing(self):
        """Turn an OSError of the file into one :class:`OutputWriteError`, closing the file."""
        try:
            yield
        except OSError as exc:
            self._closed = True
            if self._owns:
                try:  # flushing Python's buffer fails again; the descriptor is closed anyway
                    self._stream.close()
                except OSError:
                    pass
            raise OutputWriteError(f"{self._name}: writing failed: {exc.strerror or exc}") from None

    def _sync(self):
        if self._fsync and hasattr(self._stream, "fileno"):
            self._stream.flush()
            os.fsync(self._stream.fileno())

    def _check_open(self):
        if self._closed:
            raise RecordingError(f"{self._name}: the recording writer is closed")


def _create(path):
    """Open ``path`` for writing, truncated; one :class:`OutputError` if it cannot be."""
    try:
        return open(path, "wb")
    except IsADirectoryError:
        raise OutputError(f"{path}: is a directory; give a file name inside it") from None
    except OSError as exc:
        raise OutputError(f"{path}: cannot create the recording: {exc.strerror or exc}") from None


def write_mcap(recording, path):
    """Write a recording to an MCAP file.

    Parameters
    ----------
    recording : Recording
        The recording; everything in it is stored and read back exactly
        (temperatures as float32).
    path : str, Path or binary file object
        Destination.

    Raises
    ------
    OutputError
        When the file cannot be created.
    OutputWriteError
        When writing fails part-way; a file given by its path is then
        removed, since it holds only part of the recording.
    """
    writer = RecordingWriter(
        path,
        dt_ns=recording.dt_ns,
        program=recording.program,
        sensor=recording.sensor,
        machine_id=recording.machine_id,
        metadata=recording.metadata,
        processing=recording.processing,
    )
    try:
        with writer:
            writer.write_samples(
                recording.seq, recording.time_ns, recording.accel, recording.temperature_c
            )
            for event in recording.events:
                writer.write_event(event)
    except OutputWriteError as exc:
        if isinstance(path, str | os.PathLike):
            Path(path).unlink(missing_ok=True)
            raise OutputWriteError(f"{exc}; the partial file was removed") from None
        raise
