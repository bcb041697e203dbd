"""Line mode: messages as strict ASCII lines, for boards that can only ``printf``.

Grammar (one message per line, ``\\n`` or ``\\r\\n``; ``[ ]`` optional)::

    line    = sample ["*" hex4] | marker ["*" hex4] | header "*" hex4
    sample  = seq "," count "," count "," count ["," temp]
    header  = "#imu-square,1," key "=" value *("," key "=" value)   (all ten keys once)
    marker  = "#marker," seq "," text

``hex4`` is the CRC-16/CCITT-FALSE of the bytes before ``*``. The header line
always carries it; its key ``line_checksum=1`` makes it mandatory on every
other line too. A line that breaks the grammar is rejected whole. Details:
``docs/protocol.md``.
"""

import math
import re

import numpy as np

from acquisition.crc import crc16
from acquisition.messages import (
    INT32_LIMIT,
    MAX_TEXT,
    SEQ_MODULUS,
    DeviceHeader,
    Marker,
    SampleBlock,
    block_counts,
    check_header,
    check_seq,
    check_text,
)
from imu_square.errors import AcquisitionError

LINE_VERSION = 1
MAX_LINE = 512
PREFIX_HEADER = b"#imu-square,"
PREFIX_MARKER = b"#marker,"
HEADER_KEYS = (
    "model",
    "serial",
    "firmware",
    "sample_rate_hz",
    "dt_ns",
    "scale_m_s2_per_count",
    "range_m_s2",
    "noise_density_m_s2_rthz",
    "has_temperature",
    "line_checksum",
)
_FLOAT_KEYS = ("sample_rate_hz", "scale_m_s2_per_count", "range_m_s2", "noise_density_m_s2_rthz")

_PRINTABLE_RE = re.compile(rb"[\x20-\x7e]*")
_SAMPLE_RE = re.compile(
    rb"(\d{1,10}),(-?\d{1,10}),(-?\d{1,10}),(-?\d{1,10})(?:,(-?\d{1,3}(?:\.\d{1,6})?))?"
)
_UINT_RE = re.compile(rb"\d{1,19}")
_FLOAT_RE = re.compile(rb"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d{1,3})?|nan")
_HEX4_RE = re.compile(rb"[0-9A-Fa-f]{4}")


def _line(text, checksum):
    raw = text.encode("ascii")
    if checksum:
        raw += b"*%04X" % crc16(raw)
    return raw + b"\n"


def _format_float(value):
    return "nan" if math.isnan(value) else repr(float(value))


def encode_header_line(header, line_checksum=True):
    """Encode a header as a ``#imu-square`` line, always with its checksum.

    Parameters
    ----------
    header : DeviceHeader
        Header to send.
    line_checksum : bool
        Declare that every sample and marker line carries ``*hhhh`` (the
        receiver then rejects lines without it).

    Returns
    -------
    bytes
        One line.
    """
    check_header(header)
    values = {
        "model": header.model,
        "serial": header.serial,
        "firmware": header.firmware,
        "sample_rate_hz": _format_float(header.sample_rate_hz),
        "dt_ns": str(int(header.dt_ns)),
        "scale_m_s2_per_count": _format_float(header.scale_m_s2_per_count),
        "range_m_s2": _format_float(header.range_m_s2),
        "noise_density_m_s2_rthz": _format_float(header.noise_density_m_s2_rthz),
        "has_temperature": str(int(header.has_temperature)),
        "line_checksum": str(int(line_checksum)),
    }
    fields = ",".join(f"{key}={values[key]}" for key in HEADER_KEYS)
    return _line(f"#imu-square,{LINE_VERSION},{fields}", checksum=True)


def encode_block_lines(block, checksum=True):
    """Encode a sample block as one line per sample.

    Parameters
    ----------
    block : SampleBlock
        Samples; counts within int32. Flags are not carried in line mode.
    checksum : bool
        Append ``*hhhh`` to every line.

    Returns
    -------
    bytes
        ``n_samples`` lines; the temperature, if any, with two decimals. [degC]
    """
    counts = block_counts(block, "line")
    t = block.temperature_c
    tail = "" if math.isnan(t) else f",{t:.2f}"
    return b"".join(
        _line(f"{(block.seq0 + i) % SEQ_MODULUS},{x},{y},{z}{tail}", checksum)
        for i, (x, y, z) in enumerate(counts.tolist())
    )


def encode_marker_line(marker, checksum=True):
    """Encode a marker as a ``#marker`` line.

    Parameters
    ----------
    marker : Marker
        Marker to send.
    checksum : bool
        Append ``*hhhh``.

    Returns
    -------
    bytes
        One line.
    """
    check_seq("marker.seq", marker.seq)
    check_text(marker.text)
    return _line(f"#marker,{marker.seq},{marker.text}", checksum)


def _strip(line, require_checksum):
    """Drop CR and a valid ``*hhhh``; None if not printable ASCII or the checksum fails."""
    if line.endswith(b"\r"):
        line = line[:-1]
    if not _PRINTABLE_RE.fullmatch(line):
        return None
    body, star, check = line.rpartition(b"*")
    if not star:
        return None if require_checksum else line
    if b"*" in body or not _HEX4_RE.fullmatch(check) or int(check, 16) != crc16(body):
        return None
    return body


def parse_header_line(line):
    """Parse a ``#imu-square`` header line (newline removed) strictly.

    Parameters
    ----------
    line : bytes
        The line, with an optional trailing ``\\r``; its checksum is mandatory.

    Returns
    -------
    tuple of (DeviceHeader, bool) or None
        The header and whether the other lines must carry a checksum; None if
        the line breaks the grammar in any way or the header is inconsistent.
    """
    body = _strip(line, require_checksum=True)
    if body is None or not body.startswith(PREFIX_HEADER):
        return None
    parts = body[len(PREFIX_HEADER) :].split(b",")
    if parts[0] != b"%d" % LINE_VERSION or len(parts) != 1 + len(HEADER_KEYS):
        return None
    values = {}
    for part in parts[1:]:
        key, eq, value = part.partition(b"=")
        key = key.decode("ascii")
        if not eq or key not in HEADER_KEYS or key in values:
            return None
        values[key] = value
    if not all(_FLOAT_RE.fullmatch(values[key]) for key in _FLOAT_KEYS):
        return None
    if not _UINT_RE.fullmatch(values["dt_ns"]):
        return None
    if values["has_temperature"] not in (b"0", b"1") or values["line_checksum"] not in (b"0", b"1"):
        return None
    header = DeviceHeader(
        model=values["model"].decode("ascii"),
        serial=values["serial"].decode("ascii"),
        firmware=values["firmware"].decode("ascii"),
        dt_ns=int(values["dt_ns"]),
        has_temperature=values["has_temperature"] == b"1",
        mode="line",
        **{key: float(values[key]) for key in _FLOAT_KEYS},
    )
    try:
        return check_header(header), values["line_checksum"] == b"1"
    except AcquisitionError:
        return None


def _parse_marker(body):
    seq, comma, text = body[len(PREFIX_MARKER) :].partition(b",")
    if not comma or not _UINT_RE.fullmatch(seq) or int(seq) >= SEQ_MODULUS or len(text) > MAX_TEXT:
        return None
    return Marker(int(seq), text.decode("ascii"))


def parse_line(line, has_temperature, require_checksum):
    """Parse one sample or marker line (newline removed) strictly.

    Parameters
    ----------
    line : bytes
        The line, with an optional trailing ``\\r``.
    has_temperature : bool
        Whether sample lines must carry a temperature (from the last header).
    require_checksum : bool
        Reject the line unless it ends in a valid ``*hhhh`` (the last header
        said ``line_checksum=1``).

    Returns
    -------
    SampleBlock (one sample), Marker or None
        The message, or None if the line breaks the grammar in any way. Header
        lines give None here: use :func:`parse_header_line`.
    """
    body = _strip(line, require_checksum)
    if not body:
        return None
    if body.startswith(PREFIX_MARKER):
        return _parse_marker(body)
    m = _SAMPLE_RE.fullmatch(body)
    if m is None:
        return None
    seq, x, y, z, temp = m.groups()
    seq, x, y, z = int(seq), int(x), int(y), int(z)
    if seq >= SEQ_MODULUS or max(abs(x), abs(y), abs(z)) > INT32_LIMIT:
        return None
    if has_temperature != (temp is not None):
        return None
    t = math.nan if temp is None else float(temp)
    return SampleBlock(seq, np.array([[x, y, z]], np.int32), t, 0)
