"""Read a recording from MCAP, also from a file cut by a crash, a full disk or a pulled cable.

The reader walks the file's records from the start and stops cleanly at the
first incomplete or damaged record, so a cut file gives every message of its
complete chunks; :class:`RecoveryReport` says where and why reading stopped.
What the records hold is kept by a :class:`~imu_square.io.mcap.scan.Scan`.
"""

import io
import struct
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import zstandard
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.stream_reader import MAGIC_SIZE
from mcap.writer import MCAP0_MAGIC as MAGIC

from imu_square.errors import ImuSquareWarning, RecordingError
from imu_square.io.mcap.layout import MESSAGE_INDEX_ENTRY, MESSAGE_INDEX_FIELDS, RECORD_PREFIX
from imu_square.io.mcap.scan import Scan, build_recording
from imu_square.io.recording import Recording
from imu_square.io.runlog import run_outcome


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
    scan = Scan(path)
    try:
        size = f.seek(0, io.SEEK_END)
        f.seek(0)
        magic = f.read(MAGIC_SIZE)
        if size == 0:
            raise RecordingError(f"{path}: the file is empty, not an MCAP recording")
        if magic != MAGIC and MAGIC.startswith(magic):
            raise RecordingError(
                f"{path}: the file is cut after {size} bytes, inside the MCAP magic: "
                f"no complete samples"
            )
        if magic != MAGIC:
            raise RecordingError(
                f"{path}: not an MCAP file (it starts with {magic!r}, expected {MAGIC!r})"
            )
        pos = MAGIC_SIZE
        problem = ""
        complete = False
        pending = None  # (chunk body, {channel_id: offsets}, chunk start) awaiting its indexes
        while True:
            head = f.read(RECORD_PREFIX.size)
            if len(head) < RECORD_PREFIX.size:
                problem = "it ends in the middle of a record" if head else "it has no footer"
                break
            opcode, length = RECORD_PREFIX.unpack(head)
            content = pos + RECORD_PREFIX.size  # where the record's content starts [bytes]
            if length > size - content:
                problem = "it ends in the middle of a record"
                break
            body = f.read(length)
            if opcode == Opcode.MESSAGE_INDEX and pending is not None:
                channel_id, n_bytes = MESSAGE_INDEX_FIELDS.unpack_from(body)
                n_bytes = min(n_bytes, length - MESSAGE_INDEX_FIELDS.size)
                entries = np.frombuffer(
                    body,
                    MESSAGE_INDEX_ENTRY,
                    count=n_bytes // MESSAGE_INDEX_ENTRY.itemsize,
                    offset=MESSAGE_INDEX_FIELDS.size,
                )
                pending[1][channel_id] = entries["offset"]
                pos = content + length
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
            pos = content + length
            if opcode == Opcode.FOOTER:
                complete = f.read(MAGIC_SIZE) == MAGIC and pos + MAGIC_SIZE == size
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
        recording = build_recording(scan)
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
    """Read an MCAP recording written by :class:`~imu_square.io.mcap.writer.RecordingWriter`.

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
