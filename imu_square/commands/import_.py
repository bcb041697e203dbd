"""``imu-square import``: convert a CSV recording into an MCAP recording."""

import argparse
import math
import sys
import warnings

from imu_square.errors import ImuSquareError, ImuSquareWarning
from imu_square.io.csv import FORMATS, GRAVITY_AXES, read_csv
from imu_square.io.mcap import write_mcap
from imu_square.io.recording import SensorInfo
from imu_square.io.times import parse_start_time
from imu_square.program import read_program
from imu_square.units import UG, G

HELP = "convert a CSV recording to MCAP"


def register(sub):
    """Add the ``import`` subcommand."""
    p = sub.add_parser(
        "import",
        help=HELP,
        description="Read accelerometer samples from CSV, check their units against gravity, "
        "and write them with the test program to an MCAP recording.",
    )
    p.add_argument("csv", help="CSV file")
    p.add_argument(
        "--program",
        help="test program TOML the machine ran (default with --config: the monitor file's)",
    )
    p.add_argument("-o", "--output", required=True, help="MCAP file to write")
    p.add_argument(
        "--format",
        choices=sorted(FORMATS),
        default="imu-square",
        help="imu-square: time_s,accel_x,accel_y,accel_z[,temperature_c] in s and m/s^2; "
        "klipper: #time,accel_x,accel_y,accel_z in s and mm/s^2 (default: %(default)s)",
    )
    p.add_argument(
        "--gravity-axis",
        choices=GRAVITY_AXES,
        help="sensor axis that carries gravity (default: the axis with the largest mean)",
    )
    p.add_argument(
        "--columns",
        metavar="TIME,X,Y,Z[,TEMP]",
        help="header names of the columns to use, for a file with other column names",
    )
    p.add_argument(
        "--range-g",
        type=float,
        help="the sensor's full-scale range in g: samples at it are clipped and the analysis "
        "drops their cycles (default: unknown, so clipping cannot be detected)",
    )
    noise = p.add_mutually_exclusive_group()
    noise.add_argument(
        "--noise-density-ug",
        type=float,
        help="the sensor's white-noise density in ug/sqrt(Hz), for the noise floor "
        "(default: estimated from the data)",
    )
    # The option's name until 0.1, accepted with a warning for one release.
    noise.add_argument("--noise-ug", type=float, help=argparse.SUPPRESS)
    p.add_argument("--sensor-model", default="unknown", help="sensor model, e.g. ADXL355")
    p.add_argument("--machine-id", default="", help="machine the test ran on")
    p.add_argument(
        "--config",
        metavar="MONITOR.toml",
        help="the monitor file of the machine the test ran on: its machine id (which "
        "--machine-id must match) and, without --program, its program",
    )
    when = p.add_mutually_exclusive_group()
    when.add_argument(
        "--start-time",
        metavar="ISO8601",
        help="when the recording started, with its time zone (2026-09-01T02:30:00Z); needed "
        "when the file's times are seconds from the logger's power-on, not dates",
    )
    when.add_argument(
        "--relative-time",
        action="store_true",
        help="keep times that are not dates (before 2000) as they are; the monitor does "
        "not judge such a recording",
    )
    p.set_defaults(func=run)


def run(args):
    """Import the CSV and write the MCAP file."""
    machine_id, program_path = args.machine_id, args.program
    if args.config is not None:
        from imu_square.monitor.config import read_monitor

        config = read_monitor(args.config)
        if machine_id and machine_id != config.machine_id:
            raise ImuSquareError(
                f"--machine-id {machine_id!r} is not the machine of {args.config} "
                f"({config.machine_id!r})"
            )
        machine_id = config.machine_id
        if program_path is None:
            program = config.test_program()
    if program_path is not None:
        program = read_program(program_path)
    elif args.config is None:
        raise ImuSquareError("give the test program: --program PROGRAM.toml, or --config")
    start_ns = None if args.start_time is None else parse_start_time(args.start_time)
    columns = None if args.columns is None else [c.strip() for c in args.columns.split(",")]
    if args.noise_ug is not None:
        warnings.warn(
            "--noise-ug is now --noise-density-ug; the old name is accepted until the next release",
            ImuSquareWarning,
            stacklevel=2,
        )
        args.noise_density_ug = args.noise_ug
    for name in ("range_g", "noise_density_ug"):
        value = getattr(args, name)
        if value is not None and not (math.isfinite(value) and value > 0):
            raise ImuSquareError(f"--{name.replace('_', '-')} must be a number > 0, got {value!r}")
    nan = float("nan")
    sensor = SensorInfo(
        model=args.sensor_model,
        range_m_s2=nan if args.range_g is None else args.range_g * G,
        noise_density_m_s2_rthz=nan
        if args.noise_density_ug is None
        else args.noise_density_ug * UG,
    )
    recording = read_csv(
        args.csv,
        program,
        fmt=args.format,
        gravity_axis=args.gravity_axis,
        machine_id=machine_id,
        columns=columns,
        sensor=sensor,
        start_time_ns=start_ns,
        relative_time=args.relative_time,
    )
    write_mcap(recording, args.output)
    print(
        f"imported {recording.n_samples} samples ({recording.duration_s:.3f} s at "
        f"{recording.sample_rate_hz:.6g} Hz, {recording.gap_count} gaps, "
        f"{recording.lost_samples} lost) from {args.csv} to {args.output}",
        file=sys.stdout,
    )
    return 0
