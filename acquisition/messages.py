"""The three messages a board sends, independent of how they travel.

A :class:`DeviceHeader` describes the sensor, a :class:`SampleBlock` carries
consecutive raw counts, a :class:`Marker` forwards a trigger. The checks here
are the limits both wire modes share (see ``docs/protocol.md``).
"""

import math
import re
from dataclasses import dataclass

import numpy as np

from imu_square.errors import AcquisitionError
from imu_square.validation import check_option

MODES = ("binary", "line")
SEQ_MODULUS = 2**32
INT24_MIN = -(2**23)
INT24_MAX = 2**23 - 1
INT32_LIMIT = 2**31 - 1
MAX_TEXT = 120
MAX_NAME = 32
MAX_TEMPERATURE_C = 327.67

FLAG_FIFO_OVERRUN = 0x01
FLAG_SATURATED = 0x02
FLAG_TX_DROPPED = 0x04

PRINTABLE_RE = re.compile(r"[\x20-\x7e]*")
NAME_FORBIDDEN = ",=*"
TEXT_FORBIDDEN = "*"


@dataclass(frozen=True)
class DeviceHeader:
    """What a board says about itself; sent on connect, on request and every second.

    Attributes
    ----------
    model : str
        Sensor or board model, e.g. ``"ADXL355"``; 1 to 32 printable ASCII
        characters without ``,``, ``=`` or ``*``.
    serial : str
        Serial number, up to 32 characters (same alphabet).
    firmware : str
        Firmware version, up to 32 characters (same alphabet).
    sample_rate_hz : float
        Nominal output data rate. [Hz]
    dt_ns : int
        Exact nominal sample spacing, ``round(1e9 / sample_rate_hz)``; the
        recorder's time base. [ns]
    scale_m_s2_per_count : float
        Acceleration of one count. [m/s^2]
    range_m_s2 : float
        Full-scale range; counts at +-range are clipped. [m/s^2]
    noise_density_m_s2_rthz : float
        White-noise density per axis, NaN if unknown. [m/s^2/sqrt(Hz)]
    has_temperature : bool
        Whether sample blocks carry the sensor temperature.
    mode : str
        ``"binary"`` or ``"line"``: the mode the board streams in.
    """

    model: str
    serial: str
    firmware: str
    sample_rate_hz: float
    dt_ns: int
    scale_m_s2_per_count: float
    range_m_s2: float
    noise_density_m_s2_rthz: float
    has_temperature: bool
    mode: str = "binary"


@dataclass(frozen=True, eq=False)
class SampleBlock:
    """Consecutive samples as the board counted them.

    Attributes
    ----------
    seq0 : int
        Raw 32-bit sequence counter of the first sample; sample ``i`` has
        ``(seq0 + i) % 2**32``.
    counts : ndarray of int32, shape (n_samples, 3)
        Raw x, y, z counts; multiply by the header's scale for m/s^2. [counts]
    temperature_c : float
        Sensor temperature, NaN if absent. [degC]
    flags : int
        Bit set of ``FLAG_FIFO_OVERRUN``, ``FLAG_SATURATED``, ``FLAG_TX_DROPPED``.
    """

    seq0: int
    counts: np.ndarray
    temperature_c: float = math.nan
    flags: int = 0

    @property
    def n_samples(self):
        """Number of samples in the block."""
        return len(self.counts)


@dataclass(frozen=True)
class Marker:
    """A trigger forwarded by the board (CNC M-code input, "motion started", ...).

    Attributes
    ----------
    seq : int
        Raw 32-bit sequence number of the sample at which the trigger arrived.
    text : str
        Up to 120 printable ASCII characters, without ``*``.
    """

    seq: int
    text: str


def check_header(header):
    """Raise if ``header`` cannot be sent or is not self-consistent.

    Parameters
    ----------
    header : DeviceHeader
        Header to check.

    Returns
    -------
    DeviceHeader
        ``header`` unchanged.
    """
    check_option("header.mode", header.mode, MODES)
    for name in ("model", "serial", "firmware"):
        value = getattr(header, name)
        lo = 1 if name == "model" else 0
        if (
            not isinstance(value, str)
            or not lo <= len(value) <= MAX_NAME
            or not PRINTABLE_RE.fullmatch(value)
            or any(c in value for c in NAME_FORBIDDEN)
        ):
            raise AcquisitionError(
                f"header.{name} must be {lo} to {MAX_NAME} printable ASCII characters "
                f"without {NAME_FORBIDDEN!r}, got {value!r}"
            )
    for name in ("sample_rate_hz", "scale_m_s2_per_count", "range_m_s2"):
        value = getattr(header, name)
        if not (math.isfinite(value) and value > 0):
            raise AcquisitionError(f"header.{name} must be finite and > 0, got {value!r}")
    noise = header.noise_density_m_s2_rthz
    if not (math.isnan(noise) or (math.isfinite(noise) and noise > 0)):
        raise AcquisitionError(
            f"header.noise_density_m_s2_rthz must be > 0 or NaN (unknown), got {noise!r}"
        )
    expected = round(1e9 / header.sample_rate_hz)
    if (
        not isinstance(header.dt_ns, int | np.integer)
        or header.dt_ns != expected
        or not 0 < expected < 2**63
    ):
        raise AcquisitionError(
            f"header.dt_ns must equal round(1e9 / sample_rate_hz) = {expected!r} "
            f"for sample_rate_hz={header.sample_rate_hz!r}, got {header.dt_ns!r}"
        )
    if not isinstance(header.has_temperature, bool):
        raise AcquisitionError(
            f"header.has_temperature must be True or False, got {header.has_temperature!r}"
        )
    return header


def check_seq(name, seq):
    """Raise unless ``seq`` is a raw 32-bit sequence number.

    Parameters
    ----------
    name : str
        Field name for the message, e.g. ``"marker.seq"``.
    seq : int
        Value received.
    """
    if not isinstance(seq, int | np.integer) or not 0 <= seq < SEQ_MODULUS:
        raise AcquisitionError(f"{name} must be an integer in [0, 2**32), got {seq!r}")


def check_text(text):
    """Raise unless ``text`` can be a marker's text in both modes.

    Parameters
    ----------
    text : str
        Value received.
    """
    if (
        not isinstance(text, str)
        or len(text) > MAX_TEXT
        or not PRINTABLE_RE.fullmatch(text)
        or TEXT_FORBIDDEN in text
    ):
        raise AcquisitionError(
            f"marker.text must be up to {MAX_TEXT} printable ASCII characters without "
            f"{TEXT_FORBIDDEN!r}, got {text!r}"
        )


def block_counts(block, mode):
    """Check a block against the limits of ``mode`` and return its counts.

    Parameters
    ----------
    block : SampleBlock
        Block to send.
    mode : {"binary", "line"}
        Wire mode: int24 counts in binary mode, int32 in line mode.

    Returns
    -------
    ndarray of int32, shape (n_samples, 3)
        The counts. [counts]
    """
    check_seq("block.seq0", block.seq0)
    counts = np.asarray(block.counts)
    if counts.ndim != 2 or counts.shape[1] != 3 or counts.shape[0] < 1:
        raise AcquisitionError(
            f"block.counts must have shape (n_samples, 3) with n_samples >= 1, got {counts.shape!r}"
        )
    if not np.issubdtype(counts.dtype, np.integer):
        raise AcquisitionError(f"block.counts must be integers, got dtype {counts.dtype!r}")
    lo, hi = (INT24_MIN, INT24_MAX) if mode == "binary" else (-INT32_LIMIT, INT32_LIMIT)
    if counts.min() < lo or counts.max() > hi:
        raise AcquisitionError(
            f"block.counts must lie in [{lo}, {hi}] in {mode} mode, "
            f"got [{counts.min()}, {counts.max()}]"
        )
    t = block.temperature_c
    if not (math.isnan(t) or -MAX_TEMPERATURE_C <= t <= MAX_TEMPERATURE_C):
        raise AcquisitionError(
            f"block.temperature_c must be NaN or within +-{MAX_TEMPERATURE_C} degC, got {t!r}"
        )
    if not 0 <= block.flags <= 0xFF:
        raise AcquisitionError(f"block.flags must be in [0, 255], got {block.flags!r}")
    return counts.astype(np.int32)


def unwrap_seq(raw, reference):
    """Unwrap a raw 32-bit sequence number next to a known unwrapped one.

    Parameters
    ----------
    raw : int
        Raw counter value in ``[0, 2**32)``.
    reference : int
        An unwrapped sequence number within ``2**31`` samples of the answer.

    Returns
    -------
    int
        The integer congruent to ``raw`` modulo ``2**32`` closest to ``reference``.
    """
    delta = (raw - reference) % SEQ_MODULUS
    if delta >= SEQ_MODULUS // 2:
        delta -= SEQ_MODULUS
    return reference + delta
