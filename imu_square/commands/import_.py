"""``imu-square import``: convert a CSV recording into an MCAP recording."""

import argparse
import math
import sys
import warnings

from imu_square.errors import ImuSquareError, ImuSquareWarning
from imu_square.io.csv import FORMATS, GRAVITY_AXES, read_csv
from imu_square.io.mcap import write_mcap
from imu_square.io.recording import SensorInfo
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
    p.add_argument("--program", required=True, help="test program TOML the machine ran")
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
    p.set_defaults(func=run)


def run(args):
    """Import the CSV and write the MCAP file."""
    program = read_program(args.program)
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
        machine_id=args.machine_id,
        columns=columns,
        sensor=sensor,
    )
    write_mcap(recording, args.output)
    gaps = recording.gaps()
    print(
        f"imported {recording.n_samples} samples ({recording.duration_s:.3f} s at "
        f"{recording.sample_rate_hz:.6g} Hz, {len(gaps)} gaps, {recording.lost_samples} lost) "
        f"from {args.csv} to {args.output}",
        file=sys.stderr,
    )
    return 0
