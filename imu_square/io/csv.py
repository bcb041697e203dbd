"""Import accelerometer samples from CSV, checking the units against gravity.

Formats
-------
``imu-square``
    A header line ``time_s,accel_x,accel_y,accel_z`` (optionally
    ``,temperature_c``), then one sample per line in s, m/s^2 (and degC).
``klipper``
    Klipper's accelerometer dump: ``#time,accel_x,accel_y,accel_z`` in s and
    mm/s^2.

Lines starting with ``#`` before the header are comments. A file whose header
names other columns can be read by naming them with ``columns``.

Times are kept exactly as written: the seconds are parsed as decimals into
integer nanoseconds. The nominal spacing is the median time step; a step over
1.5 times it is a gap, recorded as an event and in the sequence numbers, never
filled in.

Units are never guessed silently: the mean of the gravity axis must read
about 1 g in the format's unit, otherwise the import refuses and says what the
data looks like.
"""

import decimal
from decimal import Decimal
from pathlib import Path

import numpy as np

from imu_square.errors import RecordingError
from imu_square.io.recording import AXES, Event, Recording, SensorInfo
from imu_square.io.times import is_date
from imu_square.units import G
from imu_square.validation import check_option

FORMATS = {
    # name: (expected columns, unit name, factor to m/s^2, comment-prefixed header)
    "imu-square": (("time_s", "accel_x", "accel_y", "accel_z"), "m/s^2", 1.0, False),
    "klipper": (("time", "accel_x", "accel_y", "accel_z"), "mm/s^2", 1e-3, True),
}
TEMPERATURE_COLUMN = "temperature_c"
GRAVITY_AXES = ("x", "y", "z", "-x", "-y", "-z")

# The gravity axis must read within this fraction of 1 g (a tilt up to ~40 deg).
GRAVITY_TOLERANCE = 0.25
_UNITS = (("m/s^2", G), ("mm/s^2", G * 1e3), ("g", 1.0), ("mg", 1e3))
_FORMAT_OF = {"m/s^2": "imu-square", "mm/s^2": "klipper"}
GAP_FACTOR = 1.5


def _time_ns(text):
    """Integer nanoseconds from a decimal seconds string, rounded half-even."""
    with decimal.localcontext() as ctx:
        ctx.prec = 40
        ctx.traps[decimal.InvalidOperation] = True
        value = Decimal(text.strip())
        if not value.is_finite():
            raise ValueError(text)
        return int((value * 1_000_000_000).to_integral_value(decimal.ROUND_HALF_EVEN))


def _read_lines(path):
    try:
        text = Path(path).read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise RecordingError(f"{path}: CSV file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise RecordingError(f"{path}: cannot read the CSV file: {exc}") from None
    return [(i, line.strip()) for i, line in enumerate(text.splitlines(), 1) if line.strip()]


def _split(line):
    return [c.strip() for c in line.split(",")]


def _find_header(path, lines, fmt, columns):
    """Return (index into lines of the header, names of the header's columns)."""
    expected, _, _, hash_header = FORMATS[fmt]
    for k, (lineno, line) in enumerate(lines):
        is_comment = line.startswith("#")
        names = _split(line.lstrip("#"))
        if is_comment and fmt != "klipper" and tuple(names) == FORMATS["klipper"][0]:
            raise RecordingError(
                f"{path}: line {lineno}: this is a Klipper header ({line!r}, mm/s^2), but the "
                f"format is {fmt!r}; use --format klipper"
            )
        if is_comment and not hash_header:
            continue
        if is_comment and hash_header and columns is None and tuple(names[:4]) != expected:
            continue
        return k, names
    raise RecordingError(
        f"{path}: no header line; format {fmt!r} expects "
        f"{'#' if hash_header else ''}{','.join(expected)}"
    )


def _column_indices(path, lineno, names, fmt, columns):
    """Indices of the time, x, y, z and (or None) temperature columns."""
    expected = FORMATS[fmt][0]
    if columns is not None:
        columns = tuple(columns)
        if len(columns) not in (4, 5):
            raise RecordingError(
                f"columns must name time, x, y, z and optionally temperature, got {columns!r}"
            )
        missing = [c for c in columns if c not in names]
        if missing:
            raise RecordingError(
                f"{path}: line {lineno}: header {','.join(names)!r} has no column "
                f"{missing[0]!r} named in columns"
            )
        idx = [names.index(c) for c in columns]
        return idx[:4], (idx[4] if len(idx) == 5 else None)
    allowed = [expected] + ([(*expected, TEMPERATURE_COLUMN)] if fmt == "imu-square" else [])
    if tuple(names) not in allowed:
        raise RecordingError(
            f"{path}: line {lineno}: header must be {','.join(expected)!r}"
            + (f" (optionally followed by ',{TEMPERATURE_COLUMN}')" if fmt == "imu-square" else "")
            + f" for format {fmt!r}, got {','.join(names)!r}; name the columns to use with "
            f"--columns TIME,X,Y,Z"
        )
    return [0, 1, 2, 3], (4 if len(names) == 5 else None)


def _floats(path, cells, rows, name):
    """Column of float cells, with the line number of the first bad one."""
    try:
        values = np.array(cells, dtype=np.float64)
    except ValueError:
        for cell, (lineno, _) in zip(cells, rows, strict=True):
            try:
                float(cell)
            except ValueError:
                raise RecordingError(
                    f"{path}: line {lineno}, column {name}: not a number: {cell!r}"
                ) from None
        raise
    bad = ~np.isfinite(values)
    if bad.any():
        i = int(np.argmax(bad))
        raise RecordingError(
            f"{path}: line {rows[i][0]}, column {name}: value must be finite, got {cells[i]!r}"
        )
    return values


def _gravity(path, accel, fmt, gravity_axis):
    """Check that the gravity axis reads 1 g in the format's unit."""
    _, unit, _, _ = FORMATS[fmt]
    means = accel.mean(axis=0)
    if gravity_axis is None:
        axis = int(np.argmax(np.abs(means)))
        name = AXES[axis]
    else:
        name = gravity_axis.lstrip("-")
        axis = AXES.index(name)
        sign = -1.0 if gravity_axis.startswith("-") else 1.0
        largest = AXES[int(np.argmax(np.abs(means)))]
        if largest != name or np.sign(means[axis]) != sign:
            raise RecordingError(
                f"{path}: gravity axis {gravity_axis} was given, but the mean acceleration is "
                f"({means[0]:.4g}, {means[1]:.4g}, {means[2]:.4g}): gravity is largest on "
                f"{'-' if means[AXES.index(largest)] < 0 else ''}{largest}"
            )
    reading = abs(float(means[axis]))
    looks = [u for u, g in _UNITS if abs(reading / g - 1.0) <= GRAVITY_TOLERANCE]
    if not looks:
        raise RecordingError(
            f"{path}: gravity axis {name} reads {reading:.4g} on average, which is not 1 g in "
            f"any unit (9.81 m/s^2, 9807 mm/s^2, 1 g or 1000 mg); the sensor must rest with "
            f"gravity along one axis: name that axis with --gravity-axis, or check the data"
        )
    found = looks[0]
    if found != unit:
        if found in _FORMAT_OF:
            fix = f"use --format {_FORMAT_OF[found]}"
        else:  # no format reads it: the data must be scaled
            factor = dict(_UNITS)[unit] / dict(_UNITS)[found]
            fix = f"convert the data to {unit} (multiply by {factor:.6g})"
        raise RecordingError(
            f"{path}: gravity axis {name} reads {reading:.4g} on average: this looks like "
            f"{found}, but format {fmt!r} expects {unit}; {fix}"
        )
    return name


def read_csv(
    path,
    program,
    *,
    fmt="imu-square",
    gravity_axis=None,
    sensor=None,
    machine_id="",
    columns=None,
    start_time_ns=None,
    relative_time=False,
):
    """Read accelerometer samples from a CSV file.

    Parameters
    ----------
    path : str or Path
        The CSV file.
    program : TestProgram or None
        The test program the machine ran.
    fmt : {"imu-square", "klipper"}
        File layout and units: s and m/s^2, or Klipper's s and mm/s^2.
    gravity_axis : {"x", "y", "z", "-x", "-y", "-z"}, optional
        The axis that carries gravity (sign: which way it reads); by default
        the axis with the largest mean. Its mean must be about 1 g in the
        format's unit. [-]
    sensor : SensorInfo, optional
        Sensor identity and specifications.
    machine_id : str
        Machine the test ran on.
    columns : sequence of str, optional
        Header names of the time, x, y, z (and optionally temperature)
        columns, for files whose header differs from the format's; the units
        are still the format's.
    start_time_ns : int, optional
        When the recording started: its times are moved to begin then. Needed
        when the file's times are not dates (before 2000: a logger's clock
        since its power-on), unless ``relative_time``. [ns]
    relative_time : bool
        Keep times that are not dates as they are (the monitor does not judge
        such a recording).

    Returns
    -------
    Recording
        Samples with their exact times; one ``gap`` event per gap.

    Raises
    ------
    RecordingError
        Naming the file, the line and the column, for an empty file, a wrong
        header, a non-numeric or non-finite cell, times that do not increase,
        fewer than 2 samples, units that do not match the format, or times
        that are no date without a start time.
    """
    check_option("fmt", fmt, FORMATS)
    if gravity_axis is not None:
        check_option("gravity_axis", gravity_axis, GRAVITY_AXES)
    lines = _read_lines(path)
    if not lines:
        raise RecordingError(f"{path}: the CSV file is empty")
    k, names = _find_header(path, lines, fmt, columns)
    header_line = lines[k][0]
    (it, ix, iy, iz), itemp = _column_indices(path, header_line, names, fmt, columns)
    rows = [(n, line) for n, line in lines[k + 1 :] if not line.startswith("#")]
    if len(rows) < 2:
        raise RecordingError(f"{path}: needs at least 2 samples, got {len(rows)}")
    width = len(names)
    cells = []
    for lineno, line in rows:
        row = _split(line)
        if len(row) != width:
            raise RecordingError(
                f"{path}: line {lineno}: expected {width} cells like the header, got {len(row)}"
            )
        cells.append(row)
    time_ns = np.empty(len(rows), np.int64)
    for i, row in enumerate(cells):
        try:
            time_ns[i] = _time_ns(row[it])
        except (ValueError, ArithmeticError):
            raise RecordingError(
                f"{path}: line {rows[i][0]}, column {names[it]}: not a finite number of "
                f"seconds: {row[it]!r}"
            ) from None
    columns_t = list(zip(*cells, strict=True))
    raw = np.column_stack([_floats(path, list(columns_t[j]), rows, names[j]) for j in (ix, iy, iz)])
    temperature = (
        None if itemp is None else _floats(path, list(columns_t[itemp]), rows, names[itemp])
    )
    steps = np.diff(time_ns)
    if np.any(steps <= 0):
        i = int(np.argmax(steps <= 0)) + 1
        raise RecordingError(
            f"{path}: line {rows[i][0]}: time {cells[i][it]} s does not increase "
            f"(previous line has {cells[i - 1][it]} s)"
        )
    shifted = ""
    if start_time_ns is not None:
        shifted = f", times moved to start at {start_time_ns} ns"
        time_ns += int(start_time_ns) - int(time_ns[0])
    elif not is_date(time_ns[0]) and not relative_time:
        raise RecordingError(
            f"{path}: its times start at {cells[0][it]} s, which is no date (before 2000: a "
            f"logger's clock since power-on): give the recording's start with --start-time, "
            f"e.g. 2026-09-01T02:30:00Z"
        )
    axis = _gravity(path, raw, fmt, gravity_axis)
    _, unit, factor, _ = FORMATS[fmt]
    accel = (raw * factor).astype(np.float32)

    dt_ns = int(np.rint(np.median(steps)))
    lost = np.where(steps > GAP_FACTOR * dt_ns, np.rint(steps / dt_ns).astype(np.int64) - 1, 0)
    lost = np.maximum(lost, (steps > GAP_FACTOR * dt_ns).astype(np.int64))
    seq = np.concatenate([[0], np.cumsum(1 + lost)])
    events = [
        Event(time_ns=int(time_ns[i + 1]), kind="gap", detail=f"lost={int(lost[i])}")
        for i in np.flatnonzero(lost)
    ]
    name = Path(path).name
    return Recording(
        accel=accel,
        time_ns=time_ns,
        seq=seq,
        dt_ns=dt_ns,
        program=program,
        sensor=SensorInfo() if sensor is None else sensor,
        machine_id=machine_id,
        events=events,
        temperature_c=temperature,
        metadata={"producer": "imu-square import", "source_file": name, "source_format": fmt},
        processing=[
            f"read_csv: {name}, format {fmt!r}, {unit} -> m/s^2, gravity on {axis}, "
            f"dt_ns={dt_ns} from the median step, {len(events)} gaps{shifted}"
        ],
    )
