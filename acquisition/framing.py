"""Binary mode: messages as CRC-32-protected, COBS-encoded frames.

On the wire a frame is ``0x00, COBS(body || CRC-32(body)), 0x00``; the body
starts with ``version, type``. All fields are little-endian and samples are
int24 counts. Layouts, sizes and the reasons behind them: ``docs/protocol.md``.
"""

import math
import struct

import numpy as np

from acquisition.cobs import cobs_decode, cobs_encode
from acquisition.crc import crc32
from acquisition.messages import (
    MAX_TEXT,
    DeviceHeader,
    Marker,
    SampleBlock,
    block_counts,
    check_header,
    check_seq,
    check_text,
)
from imu_square.errors import AcquisitionError

VERSION = 1
TYPE_HEADER = 0x01
TYPE_SAMPLES = 0x02
TYPE_MARKER = 0x03

MAX_SAMPLES_PER_FRAME = 255
SAMPLES_PER_FRAME = 25
TEMPERATURE_ABSENT = -32768

_SAMPLES_HEAD = struct.Struct("<BBIBBh")  # version, type, seq0, n, flags, temperature
_HEADER_HEAD = struct.Struct("<BBQddddB")  # version, type, dt_ns, rate, scale, range, noise, flags
_MARKER_HEAD = struct.Struct("<BBIB")  # version, type, seq, text length
_CRC = struct.Struct("<I")

SAMPLES_FRAME_OVERHEAD = _SAMPLES_HEAD.size + _CRC.size
MAX_FRAME = SAMPLES_FRAME_OVERHEAD + 9 * MAX_SAMPLES_PER_FRAME
MAX_ENCODED_FRAME = MAX_FRAME + 1 + MAX_FRAME // 254


def _frame(body):
    """Close a frame: append the CRC, COBS-encode, delimit before and after."""
    return b"\x00" + cobs_encode(body + _CRC.pack(crc32(body))) + b"\x00"


def encode_header_frame(header):
    """Encode a header as a binary frame (type 0x01).

    Parameters
    ----------
    header : DeviceHeader
        Header to send; checked with :func:`~acquisition.messages.check_header`.

    Returns
    -------
    bytes
        The delimited frame.
    """
    check_header(header)
    names = b"".join(
        bytes([len(s)]) + s.encode("ascii") for s in (header.model, header.serial, header.firmware)
    )
    head = _HEADER_HEAD.pack(
        VERSION,
        TYPE_HEADER,
        header.dt_ns,
        header.sample_rate_hz,
        header.scale_m_s2_per_count,
        header.range_m_s2,
        header.noise_density_m_s2_rthz,
        int(header.has_temperature),
    )
    return _frame(head + names)


def encode_block_frame(block):
    """Encode a sample block as a binary frame (type 0x02).

    Parameters
    ----------
    block : SampleBlock
        1 to 255 samples with counts within int24; temperature rounded to 0.01 degC.

    Returns
    -------
    bytes
        The delimited frame, ``binary_frame_wire_bytes(n)`` long.
    """
    counts = block_counts(block, "binary")
    n = len(counts)
    if n > MAX_SAMPLES_PER_FRAME:
        raise AcquisitionError(
            f"block.counts must hold at most {MAX_SAMPLES_PER_FRAME} samples in binary mode, "
            f"got {n}"
        )
    t = block.temperature_c
    temp = TEMPERATURE_ABSENT if math.isnan(t) else round(t * 100)
    head = _SAMPLES_HEAD.pack(VERSION, TYPE_SAMPLES, block.seq0, n, block.flags, temp)
    # int24 little-endian: the top three bytes of (count << 8) as little-endian int32
    packed = (counts.astype("<i4") << 8).view(np.uint8).reshape(-1, 4)[:, 1:]
    return _frame(head + packed.tobytes())


def encode_marker_frame(marker):
    """Encode a marker as a binary frame (type 0x03).

    Parameters
    ----------
    marker : Marker
        Marker to send.

    Returns
    -------
    bytes
        The delimited frame.
    """
    check_seq("marker.seq", marker.seq)
    check_text(marker.text)
    text = marker.text.encode("ascii")
    return _frame(_MARKER_HEAD.pack(VERSION, TYPE_MARKER, marker.seq, len(text)) + text)


def _decode_header(frame):
    if len(frame) < _HEADER_HEAD.size + 3:
        return None
    _, _, dt_ns, rate, scale, rng, noise, flags = _HEADER_HEAD.unpack_from(frame)
    names = []
    pos = _HEADER_HEAD.size
    for _ in range(3):
        if pos >= len(frame):
            return None
        n = frame[pos]
        raw = frame[pos + 1 : pos + 1 + n]
        if len(raw) != n:
            return None
        names.append(raw.decode("ascii", errors="replace"))
        pos += 1 + n
    if pos != len(frame) or flags & ~1:
        return None
    return check_header(
        DeviceHeader(*names, rate, dt_ns, scale, rng, noise, bool(flags & 1), "binary")
    )


def _decode_samples(frame):
    if len(frame) < _SAMPLES_HEAD.size:
        return None
    _, _, seq0, n, flags, temp = _SAMPLES_HEAD.unpack_from(frame)
    if n == 0 or len(frame) != _SAMPLES_HEAD.size + 9 * n:
        return None
    wide = np.zeros((3 * n, 4), np.uint8)
    wide[:, 1:] = np.frombuffer(frame, np.uint8, offset=_SAMPLES_HEAD.size).reshape(3 * n, 3)
    counts = (wide.view("<i4") >> 8).reshape(n, 3).astype(np.int32)  # arithmetic shift
    t = math.nan if temp == TEMPERATURE_ABSENT else temp / 100
    return SampleBlock(seq0, counts, t, flags)


def _decode_marker(frame):
    if len(frame) < _MARKER_HEAD.size:
        return None
    _, _, seq, n = _MARKER_HEAD.unpack_from(frame)
    raw = frame[_MARKER_HEAD.size :]
    if len(raw) != n or n > MAX_TEXT:
        return None
    return Marker(seq, raw.decode("ascii", errors="replace"))


_DECODERS = {
    TYPE_HEADER: _decode_header,
    TYPE_SAMPLES: _decode_samples,
    TYPE_MARKER: _decode_marker,
}


def intact_frame(chunk):
    """Undo COBS and check the CRC of one chunk found between two 0x00 bytes.

    Parameters
    ----------
    chunk : bytes
        Bytes between two delimiters (no 0x00).

    Returns
    -------
    bytes or None
        The frame body without its CRC, or None if the COBS structure or the
        CRC is wrong (line noise, a partial frame, garbage).
    """
    frame = cobs_decode(chunk)
    if frame is None or len(frame) < 2 + _CRC.size:
        return None
    body = frame[: -_CRC.size]
    if crc32(body) != _CRC.unpack_from(frame, len(body))[0]:
        return None
    return body


def decode_body(body):
    """Turn an intact frame body into a message.

    Parameters
    ----------
    body : bytes
        Output of :func:`intact_frame`.

    Returns
    -------
    DeviceHeader, SampleBlock, Marker or None
        The message; None for a frame type this version does not know (skip it).
    """
    if body[0] != VERSION:
        raise AcquisitionError(
            f"binary frame version must be {VERSION}, got {body[0]!r}: "
            "the board speaks a newer protocol; update imu-square"
        )
    decode = _DECODERS.get(body[1])
    if decode is None:
        return None
    message = decode(body)
    if message is None:
        raise AcquisitionError(
            f"binary frame of type {body[1]:#04x} has an intact CRC but a malformed body "
            f"({len(body)} bytes: {body[:16].hex()}...): firmware bug"
        )
    return message


def is_header_chunk(chunk):
    """Whether a chunk between two 0x00 bytes is an intact header frame.

    Parameters
    ----------
    chunk : bytes
        Bytes between two delimiters.

    Returns
    -------
    bool
    """
    if not 0 < len(chunk) <= MAX_ENCODED_FRAME:
        return False
    body = intact_frame(chunk)
    return body is not None and body[:2] == bytes([VERSION, TYPE_HEADER])


def binary_frame_wire_bytes(samples_per_frame):
    """Bytes one sample frame occupies on the wire, delimiters and COBS included.

    Parameters
    ----------
    samples_per_frame : int
        Samples in the frame (1 to 255).

    Returns
    -------
    int
        Wire bytes. [B]
    """
    payload = SAMPLES_FRAME_OVERHEAD + 9 * samples_per_frame
    return payload + 1 + payload // 254 + 2


def link_load(sample_rate_hz, baud, samples_per_frame=SAMPLES_PER_FRAME, header_bytes=120):
    """Fraction of a UART link (8N1) a binary stream uses.

    Parameters
    ----------
    sample_rate_hz : float
        Output data rate, 3 axes per sample. [Hz]
    baud : int
        Line rate; 8N1 sends 10 bits per byte. [bit/s]
    samples_per_frame : int
        Samples per frame.
    header_bytes : int
        Wire size of the header frame, sent once a second. [B]

    Returns
    -------
    float
        Used fraction of the link; above about 0.9 the board's transmit buffer
        fills up and frames are dropped.
    """
    frames_per_s = sample_rate_hz / samples_per_frame
    bytes_per_s = frames_per_s * binary_frame_wire_bytes(samples_per_frame) + header_bytes
    return bytes_per_s / (baud / 10)
