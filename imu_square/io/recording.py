"""One test, as recorded: samples, an exact time base, the program and metadata.

The :class:`Recording` is the one data object that acquisition writes, the
simulator returns and the pipeline reads. Plain array functions do the work;
file formats live in :mod:`imu_square.io.mcap` and :mod:`imu_square.io.csv`.

Time base
---------
Every sample has a device sequence number ``seq`` (unwrapped, int64) and a
timestamp ``time_ns`` (int64 nanoseconds, the sensor's own clock). Consecutive
samples normally differ by 1 in ``seq`` and by ``dt_ns`` in ``time_ns``; a jump
in ``seq`` is a gap (samples lost), never filled in.
"""

from dataclasses import dataclass, field, replace

import numpy as np

from imu_square.errors import RecordingError
from imu_square.io.runlog import parse_detail

AXES = ("x", "y", "z")


def lost_runs(seq):
    """Where a run of sequence numbers jumps: the samples lost between two kept ones.

    Parameters
    ----------
    seq : ndarray of int64, shape (n_samples,)
        Strictly increasing sequence numbers.

    Returns
    -------
    list of tuple (int, int)
        ``(index, lost)``: samples ``index - 1`` and ``index`` are ``lost + 1``
        sequence numbers apart.
    """
    jumps = np.diff(seq)
    idx = np.flatnonzero(jumps > 1)
    return [(int(i) + 1, int(jumps[i]) - 1) for i in idx]


@dataclass(frozen=True)
class Event:
    """Something that happened at one instant of a test.

    Attributes
    ----------
    time_ns : int
        When, on the recording's clock. [ns]
    kind : str
        ``"block_start"`` (a CNC marker or the simulator: a CCW/CW block starts
        moving), ``"block_end"``, ``"gap"`` (samples lost: detail
        ``lost=N[,lost_s=T][,cause=...]``, the cause of a run's missing end),
        ``"crc_error"``, ``"reconnect"``, ``"run_start"``, ``"run_end"`` or
        ``"marker"`` (any other marker line from the device or the CNC).
    direction : str
        ``"ccw"``, ``"cw"`` or ``""`` when not about a block.
    block : int
        Block index from 0, or -1 when not about a block.
    detail : str
        Free text, e.g. ``"lost=12"`` for a gap.
    """

    time_ns: int
    kind: str
    direction: str = ""
    block: int = -1
    detail: str = ""


@dataclass(frozen=True)
class SensorInfo:
    """What the recording knows about the sensor.

    Attributes
    ----------
    model : str
        Sensor model, e.g. ``"ADXL355"``.
    serial : str
        Serial number or other identity.
    noise_density_m_s2_rthz : float
        White-noise density per axis, NaN if unknown. [m/s^2/sqrt(Hz)]
    range_m_s2 : float
        Full-scale range; samples at +-range are clipped. NaN if unknown. [m/s^2]
    resolution_m_s2 : float
        One ADC step, NaN if unknown. [m/s^2]
    """

    model: str = "unknown"
    serial: str = ""
    noise_density_m_s2_rthz: float = float("nan")
    range_m_s2: float = float("nan")
    resolution_m_s2: float = float("nan")


@dataclass
class Recording:
    """Samples of one circle test with their time base, program and metadata.

    Parameters
    ----------
    accel : ndarray, shape (n_samples, 3)
        Acceleration in the sensor frame, stored as float32 as the sensor
        delivers it. [m/s^2]
    time_ns : ndarray of int64, shape (n_samples,)
        Sample times on the sensor's clock, strictly increasing. [ns]
    seq : ndarray of int64, shape (n_samples,)
        Unwrapped device sequence numbers, strictly increasing.
    dt_ns : int
        Nominal sample spacing. [ns]
    program : TestProgram or None
        The test program the machine ran, if known.
    sensor : SensorInfo
        Sensor identity and specifications.
    machine_id : str
        Which machine the test ran on.
    events : list of Event
        Block markers, gaps, reconnects, in time order.
    temperature_c : ndarray, shape (n_samples,) or None
        Sensor temperature per sample, if the device reports it. [degC]
    metadata : dict of str to str
        Anything else worth keeping (software version, source file, ...).
    processing : list of str
        Log of the steps applied to the data since acquisition.
    """

    accel: np.ndarray
    time_ns: np.ndarray
    seq: np.ndarray
    dt_ns: int
    program: object = None
    sensor: SensorInfo = field(default_factory=SensorInfo)
    machine_id: str = ""
    events: list = field(default_factory=list)
    temperature_c: np.ndarray | None = None
    metadata: dict = field(default_factory=dict)
    processing: list = field(default_factory=list)

    def __post_init__(self):
        self.accel = np.ascontiguousarray(self.accel, dtype=np.float32)
        self.time_ns = np.ascontiguousarray(self.time_ns, dtype=np.int64)
        self.seq = np.ascontiguousarray(self.seq, dtype=np.int64)
        n = self.accel.shape[0]
        if self.accel.ndim != 2 or self.accel.shape[1] != 3:
            raise RecordingError(f"accel must have shape (n, 3), got {self.accel.shape}")
        if self.time_ns.shape != (n,) or self.seq.shape != (n,):
            raise RecordingError(
                f"time_ns and seq must have shape ({n},), got {self.time_ns.shape} "
                f"and {self.seq.shape}"
            )
        if int(self.dt_ns) <= 0:
            raise RecordingError(f"dt_ns must be a positive integer, got {self.dt_ns!r}")
        self.dt_ns = int(self.dt_ns)
        for name in ("time_ns", "seq"):
            values = getattr(self, name)
            # A boolean comparison, not np.diff: reading stays within 3x the sample array.
            bad = values[1:] <= values[:-1]
            if bad.any():
                raise RecordingError(
                    f"{name} is not strictly increasing at sample {int(np.argmax(bad)) + 1}"
                )
        if self.temperature_c is not None:
            self.temperature_c = np.asarray(self.temperature_c, dtype=np.float64)
            if self.temperature_c.shape != (n,):
                raise RecordingError(
                    f"temperature_c must have shape ({n},), got {self.temperature_c.shape}"
                )
        self.events = sorted(self.events, key=lambda e: e.time_ns)

    @property
    def n_samples(self):
        """Number of samples."""
        return self.accel.shape[0]

    @property
    def sample_rate_hz(self):
        """Nominal sample rate. [Hz]"""
        return 1e9 / self.dt_ns

    @property
    def duration_s(self):
        """Time from the first to the last sample. [s]"""
        if self.n_samples < 2:
            return 0.0
        return (int(self.time_ns[-1]) - int(self.time_ns[0])) * 1e-9

    @property
    def time_s(self):
        """Sample times from the first sample, as float64. [s]"""
        return (self.time_ns - self.time_ns[0]) * 1e-9

    def gaps(self):
        """Where samples were lost.

        Returns
        -------
        list of tuple (int, int)
            ``(index, lost)``: samples ``index - 1`` and ``index`` are
            ``lost + 1`` sequence numbers apart.
        """
        return lost_runs(self.seq)

    def tail_gaps(self):
        """Samples lost after the last one: a board gone before the recorder stopped.

        The recorder writes such a gap as a ``gap`` event later than the last
        sample, its ``lost`` count in the detail.

        Returns
        -------
        list of int
            The samples each such gap lost.
        """
        if not self.n_samples:
            return []
        last = int(self.time_ns[-1])
        lost = (
            parse_detail(e.detail).get("lost", "0")
            for e in self.events
            if e.kind == "gap" and e.time_ns > last
        )
        return [int(n) for n in lost if n.isdigit() and int(n) > 0]

    @property
    def gap_count(self):
        """Gaps between samples, and after the last one (:meth:`tail_gaps`). [1]"""
        return len(self.gaps()) + len(self.tail_gaps())

    @property
    def lost_samples(self):
        """Samples lost in gaps between the first sample and the last."""
        return int(np.sum(np.diff(self.seq) - 1)) if self.n_samples > 1 else 0

    @property
    def lost_in_all(self):
        """Samples lost between samples and after the last one (:meth:`tail_gaps`)."""
        return self.lost_samples + sum(self.tail_gaps())

    def with_processing(self, step, **changes):
        """A copy with ``changes`` applied and ``step`` appended to the processing log.

        Parameters
        ----------
        step : str
            The processing step, in words, for the log.
        **changes
            Fields to replace, as :func:`dataclasses.replace` takes them.

        Returns
        -------
        Recording
        """
        return replace(self, processing=[*self.processing, step], **changes)
