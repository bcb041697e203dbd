"""CDR codec for the two ROS 2 message types the recordings use, in numpy.

``imu_square/msg/AccelBatch`` carries a run of consecutive samples; the
``geometry_msgs/msg/Vector3Stamped`` preview carries one averaged sample for
plotting in Foxglove. Both are encoded as little-endian plain CDR (the ROS 2
default, encapsulation ``CDR_LE``), byte for byte as ``mcap_ros2`` encodes
them (the tests check it), but packed and unpacked with numpy rather than one
Python call per field.

AccelBatch layout for ``n`` samples, ``nt`` temperatures (0 or ``n``) and
``no`` time offsets (0 or ``n``); every field is naturally aligned, so there
is never padding::

    offset        field
    0             encapsulation header 00 01 00 00
    4             uint32 seq0
    8             uint32 dt_ns
    12            int64  t0_ns
    20            uint32 n, then float32 x[n]
    24 + 4n       uint32 n, then float32 y[n]
    28 + 8n       uint32 n, then float32 z[n]
    32 + 12n      uint32 nt, then float32 temperature_c[nt]
    36 + 12n+4nt  uint32 no, then int32 t_offset_ns[no]
    total         40 + 12n + 4nt + 4no bytes
"""

import functools
import struct
from dataclasses import dataclass

import numpy as np

from imu_square.errors import RecordingError

CDR_LE_HEADER = b"\x00\x01\x00\x00"

ACCEL_BATCH_SCHEMA_NAME = "imu_square/msg/AccelBatch"
ACCEL_BATCH_SCHEMA = """\
# A run of consecutive accelerometer samples (imu-square recording format).
# Sample k has sequence number seq0 + k (low 32 bits of the unwrapped
# sequence number) and time t0_ns + k * dt_ns + t_offset_ns[k]; t_offset_ns is
# empty when the samples are evenly spaced, temperature_c when the sensor
# reports none. Acceleration in the sensor frame [m/s^2], temperature [degC].
uint32 seq0
uint32 dt_ns
int64 t0_ns
float32[] x
float32[] y
float32[] z
float32[] temperature_c
int32[] t_offset_ns
"""

_SEPARATOR = "=" * 80
VECTOR3_STAMPED_SCHEMA_NAME = "geometry_msgs/msg/Vector3Stamped"
VECTOR3_STAMPED_SCHEMA = f"""\
# This represents a Vector3 with reference coordinate frame and timestamp
std_msgs/Header header
Vector3 vector
{_SEPARATOR}
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
{_SEPARATOR}
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
{_SEPARATOR}
MSG: geometry_msgs/Vector3
float64 x
float64 y
float64 z
"""

_HEAD = struct.Struct("<4sIIq")
_U32 = struct.Struct("<I")
_FIXED_BYTES = 40
_INT32_MAX = 2**31 - 1


def encode_accel_batch(seq0, dt_ns, t0_ns, accel, temperature_c=None, t_offset_ns=None):
    """Encode one AccelBatch message.

    Parameters
    ----------
    seq0 : int
        Sequence number of the first sample; only its low 32 bits are stored.
    dt_ns : int
        Nominal sample spacing, in [1, 2**32). [ns]
    t0_ns : int
        Time of the first sample. [ns]
    accel : ndarray, shape (n, 3)
        Acceleration in the sensor frame, stored as float32. [m/s^2]
    temperature_c : ndarray, shape (n,), optional
        Sensor temperature, stored as float32. [degC]
    t_offset_ns : ndarray of int, shape (n,), optional
        Deviation of each sample's time from ``t0_ns + k * dt_ns``; each must
        fit in int32. [ns]

    Returns
    -------
    bytes
        The CDR message, encapsulation header included.
    """
    accel = np.asarray(accel, dtype="<f4")
    n = accel.shape[0]
    count = _U32.pack(n)
    parts = [_HEAD.pack(CDR_LE_HEADER, int(seq0) & 0xFFFFFFFF, int(dt_ns), int(t0_ns))]
    for axis in range(3):
        parts += [count, np.ascontiguousarray(accel[:, axis]).tobytes()]
    for extra, dtype in ((temperature_c, "<f4"), (t_offset_ns, "<i4")):
        if extra is None:
            parts.append(_U32.pack(0))
        else:
            parts += [count, np.asarray(extra).astype(dtype, copy=False).tobytes()]
    return b"".join(parts)


@dataclass
class AccelBatches:
    """Samples of many AccelBatch messages, decoded and joined in message order.

    Attributes
    ----------
    seq0 : ndarray of uint32, shape (n_batches,)
        Low 32 bits of each batch's first sequence number.
    dt_ns : ndarray of int64, shape (n_batches,)
        Nominal sample spacing of each batch. [ns]
    t0_ns : ndarray of int64, shape (n_batches,)
        Time of each batch's first sample. [ns]
    counts : ndarray of int64, shape (n_batches,)
        Samples in each batch.
    accel : ndarray of float32, shape (n_samples, 3)
        Acceleration. [m/s^2]
    temperature_c : ndarray of float32, shape (n_samples,) or None
        Temperature, or None when no batch has any. [degC]
    has_temperature : ndarray of bool, shape (n_batches,)
        Which batches carry temperatures.
    t_offset_ns : ndarray of int64, shape (n_samples,) or None
        Offsets from the regular grid, zero for regular batches; None when
        every batch is regular. [ns]
    """

    seq0: np.ndarray
    dt_ns: np.ndarray
    t0_ns: np.ndarray
    counts: np.ndarray
    accel: np.ndarray
    temperature_c: np.ndarray | None
    has_temperature: np.ndarray
    t_offset_ns: np.ndarray | None


def _column(rows, start, n, dtype):
    """Rows' bytes [start, start + 4n) viewed as an (n_rows, n) array of ``dtype``."""
    return rows[:, start : start + 4 * n].view(dtype)


def _subset(idx, rows, mask):
    """``idx[mask], rows[mask]``, without copying when ``mask`` is all True."""
    if mask.all():
        return idx, rows
    return idx[mask], rows[mask]


def decode_accel_batches(messages, source="<messages>"):
    """Decode AccelBatch messages, vectorised over messages of equal layout.

    Messages are grouped by (length, n, nt); each group is joined, viewed as a
    2-D uint8 array with one message per row, and its fields sliced out as
    columns.

    Parameters
    ----------
    messages : list of bytes
        CDR messages in file order.
    source : str
        File name for error messages.

    Returns
    -------
    AccelBatches

    Raises
    ------
    RecordingError
        If a message is not a well-formed AccelBatch.
    """
    n_msg = len(messages)
    lengths = np.fromiter(map(len, messages), dtype=np.int64, count=n_msg)
    seq0 = np.zeros(n_msg, np.uint32)
    dt_ns = np.zeros(n_msg, np.int64)
    t0_ns = np.zeros(n_msg, np.int64)
    counts = np.zeros(n_msg, np.int64)
    has_temp = np.zeros(n_msg, bool)
    groups = []
    for length in np.unique(lengths):
        idx = np.flatnonzero(lengths == length)
        if length < _FIXED_BYTES:
            raise RecordingError(
                f"{source}: AccelBatch message {idx[0]} is {length} bytes, shorter than "
                f"the {_FIXED_BYTES} of an empty batch"
            )
        rows = np.frombuffer(b"".join([messages[i] for i in idx]), np.uint8).reshape(
            idx.size, length
        )
        if np.any(rows[:, :4] != np.frombuffer(CDR_LE_HEADER, np.uint8)):
            raise RecordingError(f"{source}: AccelBatch message is not little-endian CDR")
        seq0[idx] = rows[:, 4:8].view("<u4")[:, 0]
        dt_ns[idx] = rows[:, 8:12].view("<u4")[:, 0]
        t0_ns[idx] = rows[:, 12:20].view("<i8")[:, 0]
        n_all = rows[:, 20:24].view("<u4")[:, 0].astype(np.int64)
        for n in np.unique(n_all):
            sub, sub_rows = _subset(idx, rows, n_all == n)
            if _FIXED_BYTES + 12 * n > length:
                raise RecordingError(f"{source}: AccelBatch message claims {n} samples")
            ny = _column(sub_rows, 24 + 4 * n, 1, "<u4")[:, 0]
            nz = _column(sub_rows, 28 + 8 * n, 1, "<u4")[:, 0]
            nt_all = _column(sub_rows, 32 + 12 * n, 1, "<u4")[:, 0]
            if np.any(ny != n) or np.any(nz != n) or np.any((nt_all != 0) & (nt_all != n)):
                raise RecordingError(f"{source}: AccelBatch message has arrays of unequal length")
            for nt in np.unique(nt_all):
                no = (length - _FIXED_BYTES - 12 * n - 4 * nt) // 4
                g_idx, g_rows = _subset(sub, sub_rows, nt_all == nt)
                no_field = _column(g_rows, 36 + 12 * n + 4 * nt, 1, "<u4")[:, 0]
                if no not in (0, n) or np.any(no_field != no):
                    raise RecordingError(
                        f"{source}: AccelBatch message length {length} does not match its "
                        f"array lengths"
                    )
                counts[g_idx] = n
                has_temp[g_idx] = nt > 0
                groups.append((g_idx, g_rows, int(n), int(nt), int(no)))

    starts = np.concatenate([[0], np.cumsum(counts)])
    total = int(starts[-1])
    accel = np.empty((total, 3), np.float32)
    offsets = np.zeros(total, np.int64) if any(g[4] for g in groups) else None
    temperature = np.full(total, np.nan, np.float32) if has_temp.any() else None
    for g_idx, rows, n, nt, no in groups:
        if n == 0:
            continue
        if g_idx[-1] - g_idx[0] + 1 == g_idx.size:  # consecutive messages: one slice, no scatter
            pos = slice(starts[g_idx[0]], starts[g_idx[-1] + 1])
        else:
            pos = (starts[g_idx][:, None] + np.arange(n)).ravel()
        for axis in range(3):
            accel[pos, axis] = _column(rows, 24 + axis * (4 + 4 * n), n, "<f4").ravel()
        if nt:
            temperature[pos] = _column(rows, 36 + 12 * n, n, "<f4").ravel()
        if no:
            offsets[pos] = _column(rows, 40 + 12 * n + 4 * nt, n, "<i4").ravel()
    return AccelBatches(seq0, dt_ns, t0_ns, counts, accel, temperature, has_temp, offsets)


@functools.cache
def _vector3_stamped_dtype(frame_id):
    """Packed record dtype of a Vector3Stamped message with ``frame_id``."""
    name = frame_id.encode() + b"\0"
    pad = -(12 + len(name)) % 8
    return np.dtype(
        [
            ("header", "S4"),
            ("sec", "<i4"),
            ("nanosec", "<u4"),
            ("frame_len", "<u4"),
            ("frame_id", f"S{len(name) + pad}"),
            ("vector", "<f8", (3,)),
        ]
    )


def encode_vector3_stamped(time_ns, vectors, frame_id="imu"):
    """Encode many Vector3Stamped messages at once.

    Parameters
    ----------
    time_ns : ndarray of int64, shape (m,)
        Header stamps; must be >= 0 and < 2**31 s. [ns]
    vectors : ndarray, shape (m, 3)
        Vector of each message. [any unit]
    frame_id : str
        Header frame id.

    Returns
    -------
    list of bytes
        One CDR message per row.
    """
    time_ns = np.asarray(time_ns, np.int64)
    dtype = _vector3_stamped_dtype(frame_id)
    rec = np.zeros(time_ns.shape[0], dtype)
    rec["header"] = CDR_LE_HEADER
    rec["sec"], rec["nanosec"] = np.divmod(time_ns, 1_000_000_000)
    rec["frame_len"] = len(frame_id.encode()) + 1
    rec["frame_id"] = frame_id.encode()
    rec["vector"] = vectors
    buf = rec.tobytes()
    size = dtype.itemsize
    return [buf[i : i + size] for i in range(0, len(buf), size)]
