"""``imu-square record``: record a test from a serial board into an MCAP file."""

from imu_square.errors import AcquisitionError

EXIT_CODES = (
    "Exit codes: 0 a complete run; 3 incomplete: samples lost, CRC errors, reconnects, an "
    "early stop (Ctrl-C, SIGTERM), or a board that went away (the port stayed lost or it sent "
    "nothing for --silence-timeout s): the file is valid and 'imu-square info' says why; 2 "
    "nothing recorded: a bad option, an output that cannot be written (checked before the "
    "port is opened) or a disk too small for the run (checked before the trigger), the port "
    "not found, no header from the board; 4 writing failed part-way (disk full): the file "
    "keeps what was flushed, 'imu-square recover' rewrites it whole."
)


HELP = "record a circle test from a serial accelerometer board into MCAP"


def register(sub):
    """Add the ``record`` subcommand."""
    p = sub.add_parser(
        "record",
        help=HELP,
        description="Read an imu-square board (binary or line protocol) from a serial port, "
        "reconnecting after unplugging, and stream the samples into an MCAP file, flushed "
        "every second. " + EXIT_CODES,
    )
    p.add_argument(
        "--port",
        required=True,
        help="serial port by a stable name (/dev/serial/by-id/..., the emulator's link) or a "
        "pyserial URL",
    )
    p.add_argument(
        "--baud",
        type=int,
        default=921600,
        help="line speed, any whole number > 0: non-standard rates (250000, 2000000) are "
        "common on USB-serial chips, and USB CDC boards ignore it (default 921600)",
    )
    p.add_argument("--program", required=True, help="program TOML the machine runs")
    p.add_argument("-o", "--output", required=True, help="output MCAP file")
    p.add_argument("--overwrite", action="store_true", help="replace the output file if it exists")
    stop = p.add_mutually_exclusive_group()
    stop.add_argument("--duration", type=float, help="stop this many seconds after the trigger")
    stop.add_argument(
        "--until-done",
        action="store_true",
        help="stop 2 s after the last block_end marker, or after the program's duration "
        "plus 2 s + 5 %% from the trigger",
    )
    p.add_argument(
        "--trigger",
        choices=("immediate", "motion", "marker"),
        default="immediate",
        help="start at once, when the table moves, or at the board's first marker "
        "(default: immediate); 3 s before the trigger are kept",
    )
    p.add_argument("--pretrigger", type=float, default=3.0, help="seconds kept before the trigger")
    p.add_argument("--machine-id", default="", help="machine the test runs on")
    p.add_argument(
        "--header-timeout",
        type=float,
        default=5.0,
        help="give up when the board sends no header within this many seconds (default 5)",
    )
    p.add_argument(
        "--silence-timeout",
        type=float,
        default=10.0,
        help="give up on a board that sends no sample for this many seconds: the port stayed "
        "lost or the board hung; the missing time is recorded as a gap and the run is "
        "incomplete (exit 3). Make it longer than any unplugging the run should ride "
        "through (default 10)",
    )
    p.add_argument(
        "--mode", choices=("binary", "line"), help="wire mode (default: detect from the header)"
    )
    p.set_defaults(func=run)


def run(args):
    """Record until the stop condition, Ctrl-C or SIGTERM; report and choose the exit code."""
    from acquisition.commands._session import report, run_recorder
    from acquisition.recorder import Recorder
    from imu_square.program import read_program

    program = read_program(args.program)
    recorder = Recorder(
        args.output,
        args.port,
        baudrate=args.baud,
        program=program,
        trigger=args.trigger,
        duration_s=args.duration,
        until_done=args.until_done,
        machine_id=args.machine_id,
        mode=args.mode,
        pretrigger_s=args.pretrigger,
        header_timeout_s=args.header_timeout,
        silence_timeout_s=args.silence_timeout,
        overwrite=args.overwrite,
    )
    status = run_recorder(recorder, quiet=args.quiet)
    if status.samples_written == 0:
        raise AcquisitionError(
            f"recording stopped ({status.stop_reason}) before any sample was written; "
            f"no file at {args.output!r}"
        )
    return report(args.output, status)
