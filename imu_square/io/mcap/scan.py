"""One linear read of an MCAP file: what its complete records hold, and the Recording.

The reader hands every complete record to a :class:`Scan`, which keeps the
schemas, channels, metadata, attachments and the messages it reads back. It
decompresses chunks itself, takes a chunk's messages through its message
indexes (touching only the messages it keeps), and decodes the samples of
many chunks at once with numpy.
"""

import io
import json
import zlib
from collections import Counter
from dataclasses import asdict

import numpy as np
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Attachment, Channel, Chunk, Metadata, Schema

from imu_square.errors import RecordingError
from imu_square.io.cdr import ACCEL_BATCH_SCHEMA_NAME, decode_accel_batches
from imu_square.io.mcap.layout import (
    CHANNEL_ID,
    MESSAGE_FIELDS,
    MESSAGE_START,
    MESSAGE_START_DTYPE,
    RECORD_PREFIX,
)
from imu_square.io.mcap.topics import ACCEL_TOPIC, EVENT_FIELDS, EVENTS_TOPIC, PROGRAM_ATTACHMENT
from imu_square.io.recording import Event, Recording, SensorInfo
from imu_square.program import parse_program

_DECODE_BYTES = 1 << 20  # AccelBatch bytes decoded at once: fast, and bounded in memory
_U32 = 2**32


class Scan:
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
            channel_id = CHANNEL_ID.unpack_from(body)[0]
            if self.wanted(channel_id):
                self.add_messages([(channel_id, [body[MESSAGE_FIELDS.size :]])], {})
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
                opcode, length = RECORD_PREFIX.unpack_from(data, pos)
                start = pos + RECORD_PREFIX.size
                pos = start + length
                if pos > end:
                    raise McapError("record overruns its chunk")
                if opcode == Opcode.MESSAGE:
                    channel_id = CHANNEL_ID.unpack_from(data, start)[0]
                    if self.wanted(channel_id):
                        if not runs or runs[-1][0] != channel_id:
                            runs.append((channel_id, []))
                        runs[-1][1].append(data[start + MESSAGE_FIELDS.size : pos])
                    else:
                        other[channel_id] += 1
                elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
                    self.add_record(opcode, data[start:pos])
        self.add_messages(runs, other)


def _indexed_messages(data, offsets, channel_id):
    """Payloads of the messages of ``channel_id`` at ``offsets`` (sorted) in a chunk's ``data``.

    The record heads are checked all at once; if any lies outside the chunk or
    is not a message of that channel, they are read one by one, which raises
    the error that names the first bad one.
    """
    size = len(data)
    if offsets.size == 0:
        return []
    content = RECORD_PREFIX.size  # where a record's content starts [bytes]
    payload = content + MESSAGE_FIELDS.size  # where a message's data starts [bytes]
    if int(offsets[-1]) + MESSAGE_START.size <= size:
        heads = np.frombuffer(data, np.uint8)[
            offsets[:, None].astype(np.intp) + np.arange(MESSAGE_START.size)
        ]
        heads = heads.view(MESSAGE_START_DTYPE)[:, 0]
        lengths = heads["record_length"]
        if (
            np.all(heads["opcode"] == Opcode.MESSAGE)
            and np.all(heads["channel_id"] == channel_id)
            and np.all(lengths <= size)  # the ends below then hold in uint64
        ):
            ends = (offsets + content + lengths).tolist()
            return [data[a + payload : b] for a, b in zip(offsets.tolist(), ends, strict=True)]
    payloads = []
    for offset in offsets.tolist():
        opcode, length, ch = MESSAGE_START.unpack_from(data, offset)
        if opcode != Opcode.MESSAGE or ch != channel_id:
            raise McapError(f"message index points to a non-message at {offset}")
        payloads.append(data[offset + payload : offset + content + length])
    return payloads


def _parse_event(data, path):
    try:
        d = json.loads(data)
        return Event(**{k: d[k] for k in EVENT_FIELDS})
    except (ValueError, KeyError, TypeError) as exc:
        raise RecordingError(f"{path}: malformed event message {data[:80]!r}: {exc}") from None


def _read_record(cls, body):
    return cls.read(ReadDataStream(io.BytesIO(body)))


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


def build_recording(scan):
    """The Recording the complete records of a :class:`Scan` hold; its samples are handed over."""
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
