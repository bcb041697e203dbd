"""Recordings as MCAP files: a streaming writer and a reader that survives a cut file.

File layout
-----------
``/imu/accel``
    ``imu_square/msg/AccelBatch`` (ros2msg schema, CDR): about 0.1 s of
    consecutive samples per message, see :mod:`imu_square.io.cdr`.
    ``log_time = publish_time = t0_ns`` of the batch.
``/imu/preview``
    ``geometry_msgs/msg/Vector3Stamped`` (CDR), the mean of the samples of
    each 1/100 s, frame ``"imu"``, for plotting in Foxglove; never read back.
``/test/events``
    JSON, one :class:`~imu_square.io.recording.Event` per message.
attachment ``program.toml``
    The test program, when the recording has one.
metadata ``sensor``, ``machine``, ``software``, ``recording``, ``sequence``
    Sensor fields, machine id, writer version and ``dt_ns``, the recording's
    metadata and processing log (as JSON text), and the first unwrapped
    sequence number.

Chunks are zstd-compressed and about 128 KiB, so a file cut by a crash or a
pulled cable loses at most a few seconds. Every message of every complete
chunk is read back. MCAP log times are unsigned: a negative sample or event
time is kept exactly in the message, and its log time is clamped to 0.

The reader walks the file's records from the start with the record classes of
the ``mcap`` package and decompresses chunks itself, so it stops cleanly at
the first incomplete or damaged record, and it decodes the samples of a whole
chunk at once with numpy.
"""

import io
import json
import math
import os
import struct
import warnings
import zlib
from collections import Counter
from contextlib import contextmanager
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Attachment, Channel, Chunk, Metadata, Schema
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, Writer

import imu_square
from imu_square.errors import (
    ImuSquareWarning,
    OutputError,
    OutputWriteError,
    RecordingError,
)
from imu_square.io.cdr import (
    ACCEL_BATCH_SCHEMA,
    ACCEL_BATCH_SCHEMA_NAME,
    VECTOR3_STAMPED_SCHEMA,
    VECTOR3_STAMPED_SCHEMA_NAME,
    decode_accel_batches,
    encode_accel_batch,
    encode_vector3_stamped,
)
from imu_square.io.recording import Event, Recording, SensorInfo
from imu_square.io.runlog import run_outcome
from imu_square.json_values import json_safe
from imu_square.program import parse_program

ACCEL_TOPIC = "/imu/accel"
PREVIEW_TOPIC = "/imu/preview"
EVENTS_TOPIC = "/test/events"
PROGRAM_ATTACHMENT = "program.toml"

BATCH_S = 0.1  # duration of one AccelBatch message [s]
PREVIEW_RATE_HZ = 100.0  # upper bound of the preview rate [Hz]
MAX_BATCH_S = 1.0

_MAGIC = b"\x89MCAP0\r\n"
_INT32_MAX = 2**31 - 1
_DECODE_BYTES = 1 << 20  # AccelBatch bytes decoded at once: fast, and bounded in memory
_U32 = 2**32
_EVENT_FIELDS = tuple(f.name for f in fields(Event))
_EVENT_SCHEMA = {
    "title": "imu_square.Event",
    "type": "object",
    "properties": {
        "time_ns": {"type": "integer", "description": "time on the recording's clock [ns]"},
        "kind": {"type": "string"},
        "direction": {"type": "string"},
        "block": {"type": "integer"},
        "detail": {"type": "string"},
    },
    "required": list(_EVENT_FIELDS),
}


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
        (every complete chunk; :func:`scan_mcap` reads it).
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
            "imu_square.Event", SchemaEncoding.JSONSchema, json.dumps(_EVENT_SCHEMA).encode()
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


@dataclass(frozen=True)
class RecoveryReport:
    """What a linear read of an MCAP file found.

    Attributes
    ----------
    samples : int
        Samples read.
    events : int
        Events read.
    last_time_ns : int
        Time of the last sample read. [ns]
    cut_at_byte : int
        Offset where reading stopped: the end of the last complete record, or
        the file size when the file is complete. [bytes]
    file_bytes : int
        Size of the file. [bytes]
    complete : bool
        Whether the file ended with its footer and magic, undamaged.
    duration_s : float
        Time from the first to the last sample read. [s]
    """

    samples: int
    events: int
    last_time_ns: int
    cut_at_byte: int
    file_bytes: int
    complete: bool
    duration_s: float = 0.0


@dataclass(frozen=True)
class McapContents:
    """A recording read from MCAP with what the reader saw on the way.

    Attributes
    ----------
    recording : Recording
        The samples, events, program and metadata.
    report : RecoveryReport
        Where reading stopped and whether the file is complete.
    channel_counts : dict of str to int
        Messages read per topic.
    problem : str
        Why reading stopped early, ``""`` for a complete file.
    """

    recording: Recording
    report: RecoveryReport
    channel_counts: dict
    problem: str


class _Scan:
    """State of one linear read: what the complete records held so far."""

    def __init__(self, path):
        self.path = path
        self.schemas = {}
        self.channels = {}
        self.counts = Counter()
        self.accel_parts = []
        self.accel_messages = []  # not yet decoded, from complete records
        self.accel_bytes = 0
        self.events = []
        self.metadata = {}
        self.attachments = {}
        self.zstd = zstandard.ZstdDecompressor()  # one context for every chunk

    def wanted(self, channel_id):
        """Whether messages of ``channel_id`` are read back (samples and events)."""
        channel = self.channels.get(channel_id)
        return channel is not None and channel.topic in (ACCEL_TOPIC, EVENTS_TOPIC)

    def add_messages(self, runs, other_counts):
        """Keep the messages of one complete record: ``runs`` of (channel_id, [data, ...])."""
        for channel_id, n in other_counts.items():
            channel = self.channels.get(channel_id)
            if channel is None:
                raise RecordingError(f"{self.path}: message on unknown channel {channel_id}")
            self.counts[channel.topic] += n
        for channel_id, payloads in runs:
            channel = self.channels[channel_id]
            self.counts[channel.topic] += len(payloads)
            if channel.topic == ACCEL_TOPIC:
                schema = self.schemas.get(channel.schema_id)
                if schema is None or schema.name != ACCEL_BATCH_SCHEMA_NAME:
                    raise RecordingError(
                        f"{self.path}: {ACCEL_TOPIC} must use schema "
                        f"{ACCEL_BATCH_SCHEMA_NAME!r}, got {getattr(schema, 'name', None)!r}"
                    )
                self.accel_messages += payloads
                self.accel_bytes += sum(map(len, payloads))
            else:
                self.events += [_parse_event(data, self.path) for data in payloads]
        if self.accel_bytes > _DECODE_BYTES:
            self.decode_pending()

    def decode_pending(self):
        """Decode the AccelBatch messages kept so far, many chunks at once."""
        if self.accel_messages:
            self.accel_parts.append(decode_accel_batches(self.accel_messages, str(self.path)))
        self.accel_messages = []
        self.accel_bytes = 0

    def add_record(self, opcode, body):
        """Keep a top-level record other than a chunk or a message index."""
        if opcode == Opcode.MESSAGE:
            channel_id = struct.unpack_from("<H", body)[0]
            if self.wanted(channel_id):
                self.add_messages([(channel_id, [body[22:]])], {})
            else:
                self.add_messages([], {channel_id: 1})
        elif opcode == Opcode.SCHEMA:
            schema = _read_record(Schema, body)
            self.schemas[schema.id] = schema
        elif opcode == Opcode.CHANNEL:
            channel = _read_record(Channel, body)
            self.channels[channel.id] = channel
        elif opcode == Opcode.METADATA:
            meta = _read_record(Metadata, body)
            self.metadata[meta.name] = meta.metadata
        elif opcode == Opcode.ATTACHMENT:
            att = _read_record(Attachment, body)
            self.attachments[att.name] = att.data

    def add_chunk(self, body, indexes):
        """Keep the messages of one chunk, using its message indexes if given.

        ``indexes`` maps channel id to the offsets of that channel's messages
        in the uncompressed chunk; with them the reader touches only the
        messages it keeps. Without them (the indexes were cut off, or name a
        channel this chunk defines) it walks every record of the chunk.
        """
        chunk = _read_record(Chunk, body)
        if chunk.compression == "zstd":
            data = self.zstd.decompress(chunk.data, max_output_size=chunk.uncompressed_size)
        elif chunk.compression == "":
            data = chunk.data
        else:
            raise RecordingError(
                f"{self.path}: chunk compression must be 'zstd' or none, got {chunk.compression!r}"
            )
        if len(data) != chunk.uncompressed_size:
            raise McapError("chunk size does not match its header")
        if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
            raise McapError("chunk CRC mismatch")
        unpack = struct.unpack_from
        runs, other = [], Counter()  # runs: (channel_id, [data, ...]) in reading order
        if indexes is not None and all(ch in self.channels for ch in indexes):
            for channel_id, offsets in indexes.items():
                if not self.wanted(channel_id):
                    other[channel_id] += offsets.size
                    continue
                runs.append((channel_id, _indexed_messages(data, np.sort(offsets), channel_id)))
        else:
            pos, end = 0, len(data)
            while pos < end:
                opcode, length = unpack("<BQ", data, pos)
                start = pos + 9
                pos = start + length
                if pos > end:
                    raise McapError("record overruns its chunk")
                if opcode == Opcode.MESSAGE:
                    channel_id = unpack("<H", data, start)[0]
                    if self.wanted(channel_id):
                        if not runs or runs[-1][0] != channel_id:
                            runs.append((channel_id, []))
                        runs[-1][1].append(data[start + 22 : pos])
                    else:
                        other[channel_id] += 1
                elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
                    self.add_record(opcode, data[start:pos])
        self.add_messages(runs, other)


_MESSAGE_HEAD = 11  # opcode (1), record length (8), channel id (2)


def _indexed_messages(data, offsets, channel_id):
    """Payloads of the messages of ``channel_id`` at ``offsets`` (sorted) in a chunk's ``data``.

    The record heads are checked all at once; if any lies outside the chunk or
    is not a message of that channel, they are read one by one, which raises
    the error that names the first bad one.
    """
    size = len(data)
    if offsets.size == 0:
        return []
    if int(offsets[-1]) + _MESSAGE_HEAD <= size:
        heads = np.frombuffer(data, np.uint8)[
            offsets[:, None].astype(np.intp) + np.arange(_MESSAGE_HEAD)
        ]
        lengths = heads[:, 1:9].copy().view("<u8")[:, 0]
        channels = heads[:, 9:11].copy().view("<u2")[:, 0]
        if (
            np.all(heads[:, 0] == Opcode.MESSAGE)
            and np.all(channels == channel_id)
            and np.all(lengths <= size)  # the ends below then hold in uint64
        ):
            ends = (offsets + 9 + lengths).tolist()
            return [data[a + 31 : b] for a, b in zip(offsets.tolist(), ends, strict=True)]
    payloads = []
    for offset in offsets.tolist():
        opcode, length, ch = struct.unpack_from("<BQH", data, offset)
        if opcode != Opcode.MESSAGE or ch != channel_id:
            raise McapError(f"message index points to a non-message at {offset}")
        payloads.append(data[offset + 31 : offset + 9 + length])
    return payloads


def _parse_event(data, path):
    try:
        d = json.loads(data)
        return Event(**{k: d[k] for k in _EVENT_FIELDS})
    except (ValueError, KeyError, TypeError) as exc:
        raise RecordingError(f"{path}: malformed event message {data[:80]!r}: {exc}") from None


def _read_record(cls, body):
    return cls.read(ReadDataStream(io.BytesIO(body)))


_DAMAGE = (McapError, zstandard.ZstdError, struct.error, ValueError)  # ValueError: bad values


def _add_chunk(scan, body, indexes, start):
    """Add a chunk to the scan; return why it is damaged, or ``""``."""
    try:
        scan.add_chunk(body, indexes)
    except _DAMAGE as exc:
        return f"it is damaged at byte {start} ({exc})"
    return ""


def _open(path):
    """(file object, name, whether to close it) for a path or a binary stream."""
    if hasattr(path, "read"):
        return path, getattr(path, "name", "<stream>"), False
    try:
        return open(path, "rb"), Path(path), True
    except FileNotFoundError:
        raise RecordingError(f"{path}: recording not found") from None
    except OSError as exc:
        raise RecordingError(f"{path}: cannot open the recording: {exc}") from None


def _scan_file(path):
    """Read every complete record of ``path``; return (scan, cut_at, size, complete, problem)."""
    f, path, owned = _open(path)
    scan = _Scan(path)
    try:
        size = f.seek(0, io.SEEK_END)
        f.seek(0)
        magic = f.read(8)
        if size == 0:
            raise RecordingError(f"{path}: the file is empty, not an MCAP recording")
        if magic != _MAGIC and _MAGIC.startswith(magic):
            raise RecordingError(
                f"{path}: the file is cut after {size} bytes, inside the MCAP magic: "
                f"no complete samples"
            )
        if magic != _MAGIC:
            raise RecordingError(
                f"{path}: not an MCAP file (it starts with {magic!r}, expected {_MAGIC!r})"
            )
        pos = 8
        problem = ""
        complete = False
        pending = None  # (chunk body, {channel_id: offsets}, chunk start) awaiting its indexes
        while True:
            head = f.read(9)
            if len(head) < 9:
                problem = "it ends in the middle of a record" if head else "it has no footer"
                break
            opcode, length = struct.unpack("<BQ", head)
            if length > size - pos - 9:
                problem = "it ends in the middle of a record"
                break
            body = f.read(length)
            if opcode == Opcode.MESSAGE_INDEX and pending is not None:
                channel_id, n_bytes = struct.unpack_from("<HI", body)
                entries = np.frombuffer(body, "<u8", count=min(n_bytes, length - 6) // 8, offset=6)
                pending[1][channel_id] = entries[1::2]
                pos += 9 + length
                continue
            if pending is not None:
                problem = _add_chunk(scan, *pending)
                if problem:
                    pos = pending[2]
                    pending = None
                    break
                pending = None
            try:
                if opcode == Opcode.CHUNK:
                    pending = (body, {}, pos)
                else:
                    scan.add_record(opcode, body)
            except _DAMAGE as exc:
                problem = f"it is damaged at byte {pos} ({exc})"
                break
            pos += 9 + length
            if opcode == Opcode.FOOTER:
                complete = f.read(8) == _MAGIC and pos + 8 == size
                if complete:
                    pos = size
                else:
                    problem = "it does not end with the MCAP magic after its footer"
                break
        if pending is not None:  # the last chunk is whole but its indexes may be cut
            damage = _add_chunk(scan, pending[0], None, pending[2])
            if damage:
                problem, pos = damage, pending[2]
    finally:
        if owned:
            f.close()
    return scan, pos, size, complete, problem


def _sensor_from(meta):
    if not meta:
        return SensorInfo()
    defaults = asdict(SensorInfo())
    values = {}
    for key, default in defaults.items():
        if key in meta:
            values[key] = float(meta[key]) if isinstance(default, float) else meta[key]
    return SensorInfo(**values)


def _unwrap_starts(seq0, counts, t0_ns, dt_ns, first_seq):
    """Unwrapped first sequence number of each batch from its low 32 bits.

    The step between batches is the smallest one consistent with the low 32
    bits, plus whole multiples of 2**32 when the time between the batches
    says that many samples were lost (a gap of over 2**32 samples).
    """
    seq0 = seq0.astype(np.int64)
    start0 = first_seq if first_seq is not None and first_seq % _U32 == seq0[0] else seq0[0]
    steps = (seq0[1:] - (seq0[:-1] + counts[:-1])) % _U32 + counts[:-1]
    elapsed = (t0_ns[1:] - t0_ns[:-1]) / dt_ns[:-1]
    steps += _U32 * np.maximum(0, np.rint((elapsed - steps) / _U32)).astype(np.int64)
    return start0 + np.concatenate([[0], np.cumsum(steps)])


def _ramp(base_per_batch, step_per_batch, counts, block=1 << 20):
    """Samples ``base[b] + step[b] * i`` (i: sample index) for the samples of each batch b.

    Built in place block by block, so no temporary is as large as the result.
    """
    out = np.repeat(base_per_batch, counts)
    if np.all(step_per_batch == step_per_batch[0]):
        step = int(step_per_batch[0])
        for a in range(0, out.shape[0], block):
            b = min(out.shape[0], a + block)
            out[a:b] += np.arange(a, b, dtype=np.int64) * step
    else:
        out += np.arange(out.shape[0], dtype=np.int64) * np.repeat(step_per_batch, counts)
    return out


def _build_recording(scan):
    path = scan.path
    scan.decode_pending()
    parts = [p for p in scan.accel_parts if p.counts.size]
    if not parts or sum(int(p.counts.sum()) for p in parts) == 0:
        raise RecordingError(f"{path}: no complete samples on {ACCEL_TOPIC} in the file")
    cat = np.concatenate
    counts = cat([p.counts for p in parts])
    keep = counts > 0
    counts = counts[keep]
    seq0 = cat([p.seq0 for p in parts])[keep]
    dt_b = cat([p.dt_ns for p in parts])[keep]
    t0 = cat([p.t0_ns for p in parts])[keep]
    has_temp = cat([p.has_temperature for p in parts])[keep]
    accel = cat([p.accel for p in parts])
    temperature = None
    if has_temp.any():
        if not has_temp.all():
            raise RecordingError(f"{path}: only some batches carry temperatures")
        temperature = cat([p.temperature_c for p in parts]).astype(np.float64)
    offsets_parts = None  # regular batches throughout: no zeros made to be thrown away
    if any(p.t_offset_ns is not None for p in parts):
        offsets_parts = [
            np.zeros(p.accel.shape[0], np.int64) if p.t_offset_ns is None else p.t_offset_ns
            for p in parts
        ]
    scan.accel_parts = []
    del parts

    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    meta = scan.metadata
    first_seq = meta.get("sequence", {}).get("first_seq")
    starts = _unwrap_starts(seq0, counts, t0, dt_b, None if first_seq is None else int(first_seq))
    seq = _ramp(starts - first, np.ones_like(counts), counts)
    time_ns = _ramp(t0 - first * dt_b, dt_b, counts)
    if offsets_parts is not None:
        time_ns += np.concatenate(offsets_parts)
    del offsets_parts

    try:
        dt_ns = int(meta.get("software", {}).get("dt_ns", dt_b[0]))
        rec_meta = meta.get("recording", {})
        metadata = json.loads(rec_meta.get("metadata", "{}"))
        processing = json.loads(rec_meta.get("processing", "[]"))
        sensor = _sensor_from(meta.get("sensor"))
    except (ValueError, TypeError) as exc:
        raise RecordingError(f"{path}: malformed metadata record: {exc}") from None
    program = None
    if PROGRAM_ATTACHMENT in scan.attachments:
        try:
            text = scan.attachments[PROGRAM_ATTACHMENT].decode()
        except UnicodeDecodeError:
            raise RecordingError(f"{path}: the program attachment is not UTF-8 text") from None
        program = parse_program(text, f"{path}:{PROGRAM_ATTACHMENT}")
    try:
        return Recording(
            accel=accel,
            time_ns=time_ns,
            seq=seq,
            dt_ns=dt_ns,
            program=program,
            sensor=sensor,
            machine_id=meta.get("machine", {}).get("machine_id", ""),
            events=scan.events,
            temperature_c=temperature,
            metadata=metadata,
            processing=processing,
        )
    except RecordingError as exc:
        raise RecordingError(f"{path}: {exc}") from None


def scan_mcap(path):
    """Read an MCAP recording, complete or cut, without warning.

    Parameters
    ----------
    path : str or Path
        The MCAP file.

    Returns
    -------
    McapContents

    Raises
    ------
    RecordingError
        If the file is missing, is not MCAP, or holds no complete sample.
    """
    scan, cut_at, size, complete, problem = _scan_file(path)
    try:
        recording = _build_recording(scan)
    except RecordingError as exc:
        if problem:
            raise RecordingError(f"{exc} (reading stopped at byte {cut_at}: {problem})") from None
        raise
    report = RecoveryReport(
        samples=recording.n_samples,
        events=len(recording.events),
        last_time_ns=int(recording.time_ns[-1]),
        cut_at_byte=cut_at,
        file_bytes=size,
        complete=complete,
        duration_s=recording.duration_s,
    )
    return McapContents(recording, report, dict(scan.counts), problem)


def read_mcap(path):
    """Read an MCAP recording written by :class:`RecordingWriter`.

    A file cut short (a crash, a full disk, a pulled cable) gives every
    sample of its complete chunks, with an :class:`ImuSquareWarning` saying
    how many and where the file was cut. A run whose end is missing (the
    recorder wrote a gap after its last sample: the board went away) warns
    too, saying how much is missing and why.

    Parameters
    ----------
    path : str or Path
        The MCAP file.

    Returns
    -------
    Recording

    Raises
    ------
    RecordingError
        If the file is missing, is not MCAP, or holds no complete sample.
    """
    contents = scan_mcap(path)
    if not contents.report.complete:
        r, rec = contents.report, contents.recording
        warnings.warn(
            f"{path}: incomplete MCAP file ({contents.problem}): read {r.samples} samples "
            f"({rec.duration_s:.3f} s) and {r.events} events from the complete chunks; the "
            f"file is cut at byte {r.cut_at_byte} of {r.file_bytes}; "
            f"'imu-square recover' rewrites it whole",
            ImuSquareWarning,
            stacklevel=2,
        )
    outcome = run_outcome(contents.recording)
    if outcome is not None and outcome.lost_at_end:
        warnings.warn(
            f"{path}: the run's end is missing: {'; '.join(outcome.problems)}",
            ImuSquareWarning,
            stacklevel=2,
        )
    return contents.recording


def recover_mcap(src, dst):
    """Read what is complete in a damaged MCAP file and write it as a whole file.

    Parameters
    ----------
    src : str or Path
        The damaged (e.g. truncated) MCAP file.
    dst : str or Path
        The repaired file, with summary and indexes.

    Returns
    -------
    RecoveryReport
        What was recovered from ``src``.

    Raises
    ------
    RecordingError
        If nothing is recoverable.
    """
    contents = scan_mcap(src)
    write_mcap(contents.recording, dst)
    return contents.report


def summarize(recording):
    """A JSON-ready summary of a recording, for ``imu-square info``.

    Parameters
    ----------
    recording : Recording
        The recording.

    Returns
    -------
    dict
        ``samples``, ``duration_s`` [s], ``sample_rate_hz`` [Hz], ``dt_ns``
        [ns], ``start_time_ns`` [ns], ``gaps`` (count, lost), ``channels``
        (axes and temperature), ``program`` (file units) or None, ``sensor``
        (NaN as None), ``machine_id``, ``events`` (count by kind),
        ``metadata``, ``processing``, and ``run``: how the recorder said the
        run went (:class:`~imu_square.io.runlog.RunOutcome`), None for a
        file without a ``run_end`` event.
    """
    gaps = recording.gaps()
    program = recording.program
    outcome = run_outcome(recording)
    return {
        "samples": recording.n_samples,
        "duration_s": recording.duration_s,
        "sample_rate_hz": recording.sample_rate_hz,
        "dt_ns": recording.dt_ns,
        "start_time_ns": int(recording.time_ns[0]) if recording.n_samples else None,
        "gaps": {"count": len(gaps), "lost": recording.lost_samples},
        "channels": ["accel_x", "accel_y", "accel_z"]
        + (["temperature_c"] if recording.temperature_c is not None else []),
        "program": None
        if program is None
        else {
            **program.to_mapping(),
            # one period per feed in a multi-feed program
            "period_s": program.period_s
            if program.n_feeds == 1
            else [program.at_feed(f).period_s for f in range(program.n_feeds)],
            "n_blocks": program.n_blocks,
            "duration_s": program.duration_s,
        },
        "sensor": json_safe(recording.sensor),
        "machine_id": recording.machine_id,
        "events": dict(sorted(Counter(e.kind for e in recording.events).items())),
        "metadata": dict(recording.metadata),
        "processing": list(recording.processing),
        "run": None if outcome is None else outcome.to_json_dict(),
    }
