"""The wire protocol between an accelerometer board and the recorder: public API.

Two modes carry the same three messages (header, sample block, marker):

- **binary** (:mod:`acquisition.framing`): COBS frames delimited by 0x00
  before *and* after, each ``version, type, body, CRC-32``, little-endian,
  samples as int24 counts;
- **line** (:mod:`acquisition.line_mode`): ASCII lines ``seq,ax,ay,az[,temp][*hhhh]``
  for hobby boards, with ``#imu-square,...`` header and ``#marker,...`` lines.

The host asks for a header by writing :data:`REQUEST_HEADER`. The byte
layouts, CRC parameters, handshake and resynchronisation rules are specified in
``docs/protocol.md``; this package is their reference implementation. Encoders
raise :class:`~imu_square.errors.AcquisitionError` on values the protocol
cannot carry. :class:`Parser` never raises on damaged input: damage is counted
in :class:`ParserStats` and the damaged frame or line is dropped whole.
"""

from dataclasses import dataclass

from acquisition.framing import (
    MAX_ENCODED_FRAME,
    MAX_SAMPLES_PER_FRAME,
    SAMPLES_PER_FRAME,
    TEMPERATURE_ABSENT,
    VERSION,
    binary_frame_wire_bytes,
    decode_body,
    encode_block_frame,
    encode_header_frame,
    encode_marker_frame,
    intact_frame,
    is_header_chunk,
    link_load,
)
from acquisition.line_mode import (
    MAX_LINE,
    PREFIX_HEADER,
    encode_block_lines,
    encode_header_line,
    encode_marker_line,
    parse_header_line,
    parse_line,
)
from acquisition.messages import (
    FLAG_FIFO_OVERRUN,
    FLAG_SATURATED,
    FLAG_TX_DROPPED,
    INT24_MAX,
    INT24_MIN,
    MODES,
    SEQ_MODULUS,
    DeviceHeader,
    Marker,
    SampleBlock,
    check_header,
    unwrap_seq,
)
from imu_square.validation import check_option

__all__ = [
    "FLAG_FIFO_OVERRUN",
    "FLAG_SATURATED",
    "FLAG_TX_DROPPED",
    "INT24_MAX",
    "INT24_MIN",
    "MAX_SAMPLES_PER_FRAME",
    "MODES",
    "REQUEST_HEADER",
    "SAMPLES_PER_FRAME",
    "SEQ_MODULUS",
    "TEMPERATURE_ABSENT",
    "VERSION",
    "DeviceHeader",
    "Marker",
    "Parser",
    "ParserStats",
    "SampleBlock",
    "binary_frame_wire_bytes",
    "check_header",
    "encode_block",
    "encode_header",
    "encode_marker",
    "link_load",
    "unwrap_seq",
]

REQUEST_HEADER = b"?\n"


def encode_header(header, *, checksum=True):
    """Encode a header in the mode it names.

    Parameters
    ----------
    header : DeviceHeader
        The header; ``header.mode`` selects binary frame or line.
    checksum : bool
        Line mode only: declare (``line_checksum=1``) that every sample and
        marker line will carry ``*hhhh``. The header line always carries one.

    Returns
    -------
    bytes
        One delimited binary frame, or one line.
    """
    check_header(header)
    if header.mode == "binary":
        return encode_header_frame(header)
    return encode_header_line(header, checksum)


def encode_block(block, mode="binary", *, checksum=True):
    """Encode a block of samples.

    Parameters
    ----------
    block : SampleBlock
        Samples; in binary mode at most 255, with counts within int24.
    mode : {"binary", "line"}
        Wire mode.
    checksum : bool
        Line mode only: append ``*hhhh`` (CRC-16/CCITT-FALSE) to every line.

    Returns
    -------
    bytes
        One delimited binary frame, or one line per sample. Line mode carries
        no flags; both modes round the temperature to 0.01 degC.
    """
    if check_option("mode", mode, MODES) == "binary":
        return encode_block_frame(block)
    return encode_block_lines(block, checksum)


def encode_marker(marker, mode="binary", *, checksum=True):
    """Encode a marker.

    Parameters
    ----------
    marker : Marker
        Marker to send.
    mode : {"binary", "line"}
        Wire mode.
    checksum : bool
        Line mode only: append ``*hhhh`` (CRC-16/CCITT-FALSE).

    Returns
    -------
    bytes
        One delimited binary frame, or one line.
    """
    if check_option("mode", mode, MODES) == "binary":
        return encode_marker_frame(marker)
    return encode_marker_line(marker, checksum)


@dataclass
class ParserStats:
    """Counters of a :class:`Parser`, updated by every ``feed``.

    Attributes
    ----------
    frames_ok : int
        Binary frames accepted (header, samples, marker).
    crc_errors : int
        Binary chunks rejected: bad COBS structure, too long, or bad CRC.
    lines_ok : int
        Lines accepted in line mode.
    lines_bad : int
        Lines rejected in line mode (grammar, range or checksum): the line-mode
        equivalent of a CRC error.
    frames_ignored : int
        Intact binary frames of a type this version does not know (skipped).
    samples_ok : int
        Samples delivered in accepted blocks.
    resyncs : int
        Times an accepted frame or line followed one or more rejected ones.
    bytes_discarded : int
        Bytes dropped: rejected binary chunks (without their 0x00 delimiters),
        rejected lines (with their newline), every non-zero byte before the
        first header while the mode is being detected, and in line mode every
        sample or marker line before the first header.
    """

    frames_ok: int = 0
    crc_errors: int = 0
    lines_ok: int = 0
    lines_bad: int = 0
    frames_ignored: int = 0
    samples_ok: int = 0
    resyncs: int = 0
    bytes_discarded: int = 0

    @property
    def errors(self):
        """Rejected frames plus rejected lines."""
        return self.crc_errors + self.lines_bad


class Parser:
    """Turn a byte stream from a board into headers, sample blocks and markers.

    Feed it whatever the serial port returns, in any chunking: the result does
    not depend on where the stream is split. Damaged frames or lines are
    dropped whole and counted in :attr:`stats`; the parser resynchronises on
    the next 0x00 (binary) or newline (line mode). An intact binary frame that
    breaks the protocol (unknown version, impossible header) raises
    :class:`~imu_square.errors.AcquisitionError`: that is a firmware bug, not
    line noise. In line mode, sample and marker lines before the first header
    are discarded: whether they need a temperature and a checksum is unknown.

    Parameters
    ----------
    mode : {None, "binary", "line"}
        Wire mode. None detects it from the first intact header, binary or line;
        everything before that header is discarded.

    Attributes
    ----------
    mode : str or None
        Current mode (None until detected).
    header : DeviceHeader or None
        Last header received.
    stats : ParserStats
        Counters.
    """

    def __init__(self, mode=None):
        self.mode = None if mode is None else check_option("mode", mode, MODES)
        self.header = None
        self.stats = ParserStats()
        self._buf = bytearray()
        self._skipping = False
        self._in_error = False
        self._require_checksum = False

    @property
    def buffered_bytes(self):
        """Bytes fed but not parsed yet: the start of a frame or line awaiting its end. [B]"""
        return len(self._buf)

    def feed(self, data):
        """Parse more bytes.

        Parameters
        ----------
        data : bytes-like
            The next bytes of the stream.

        Returns
        -------
        list of DeviceHeader, SampleBlock or Marker
            Messages completed by these bytes, in stream order.
        """
        self._buf += data
        if self.mode is None and not self._detect():
            return []
        out = []
        if self.mode == "binary":
            self._feed_units(0, MAX_ENCODED_FRAME, self._chunk, out)
        else:
            self._feed_units(10, MAX_LINE, self._line, out)
        return out

    def _feed_units(self, delimiter, max_len, handle, out):
        """Hand every complete unit to ``handle``; skip units longer than ``max_len``."""
        newline = int(delimiter == 10)  # a rejected line's newline counts as discarded
        buf = self._buf
        start = 0
        while (end := buf.find(delimiter, start)) >= 0:
            unit = bytes(buf[start:end])
            start = end + 1
            if self._skipping:
                self._skipping = False
                self.stats.bytes_discarded += len(unit) + newline
            elif len(unit) > max_len:
                self._reject(len(unit) + newline)
            elif unit:
                handle(unit, out)
        del buf[:start]
        if len(buf) > max_len:  # cannot become a valid unit: drop it now, skip the rest
            if not self._skipping:
                self._reject(0)
                self._skipping = True
            self.stats.bytes_discarded += len(buf)
            buf.clear()

    def _reject(self, n_bytes):
        if self.mode == "binary":
            self.stats.crc_errors += 1
        else:
            self.stats.lines_bad += 1
        self.stats.bytes_discarded += n_bytes
        self._in_error = True

    def _accept(self, message, out):
        if self._in_error:
            self.stats.resyncs += 1
            self._in_error = False
        if isinstance(message, DeviceHeader):
            self.header = message
        elif isinstance(message, SampleBlock):
            self.stats.samples_ok += message.n_samples
        out.append(message)

    def _chunk(self, chunk, out):
        body = intact_frame(chunk)
        if body is None:
            self._reject(len(chunk))
            return
        message = decode_body(body)
        if message is None:
            self.stats.frames_ignored += 1
            return
        self.stats.frames_ok += 1
        self._accept(message, out)

    def _line(self, line, out):
        if line == b"\r":  # an empty CRLF line, like an empty LF line, is no message
            return
        if line.startswith(PREFIX_HEADER):
            parsed = parse_header_line(line)
            message = None
            if parsed is not None:
                message, self._require_checksum = parsed
        elif self.header is None:  # temperature and checksum rules unknown: not yet usable
            self.stats.bytes_discarded += len(line) + 1
            return
        else:
            message = parse_line(line, self.header.has_temperature, self._require_checksum)
        if message is None:
            self._reject(len(line) + 1)
            return
        self.stats.lines_ok += 1
        self._accept(message, out)

    def _detect(self):
        """Find the first intact header of either mode; True once the mode is known.

        The header that *ends* first wins, so the answer does not depend on how
        the stream was split.
        """
        buf = bytes(self._buf)
        best = None  # (end, start, mode)
        start = 0
        while (end := buf.find(b"\x00", start)) >= 0:
            if is_header_chunk(buf[start:end]):
                best = (end, start, "binary")
                break
            start = end + 1
        start = 0
        while (end := buf.find(b"\n", start)) >= 0 and (best is None or end < best[0]):
            # A 0x00 never belongs to a text line: a header line starts after the last one,
            # wherever the stream was split (a split feed drops bytes up to a 0x00 early).
            nul = buf.rfind(b"\x00", start, end)
            first = start if nul < 0 else nul + 1
            line = buf[first:end]
            if len(line) <= MAX_LINE and parse_header_line(line) is not None:
                best = (end, first, "line")
                break
            start = end + 1
        if best is None:
            # A header yet to come starts after the last delimiter of its mode.
            cut = min(buf.rfind(b"\x00"), buf.rfind(b"\n")) + 1
            cut = max(cut, len(buf) - MAX_ENCODED_FRAME)
        else:
            _, cut, self.mode = best
        self.stats.bytes_discarded += cut - buf.count(0, 0, cut)
        del self._buf[:cut]
        return best is not None
