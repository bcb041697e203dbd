"""``imu-square record``: record a test from a serial board into an MCAP file."""

import signal
import sys

from imu_square.errors import AcquisitionError

EXIT_INCOMPLETE = 3


def register(sub):
    """Add the ``record`` subcommand."""
    p = sub.add_parser(
        "record",
        help="record a circle test from a serial accelerometer board into MCAP",
        description="Read an imu-square board (binary or line protocol) from a serial port, "
        "reconnecting after unplugging, and stream the samples into an MCAP file, flushed "
        "every second. Exit code 0: complete run; 3: incomplete (samples lost, CRC errors, "
        "reconnects or an early stop; the file is still valid); 2: user error.",
    )
    p.add_argument(
        "--port",
        required=True,
        help="serial port by a stable name (/dev/serial/by-id/..., the emulator's link) or a "
        "pyserial URL",
    )
    p.add_argument("--baud", type=int, default=921600, help="line speed (default 921600)")
    p.add_argument("--program", required=True, help="program TOML the machine runs")
    p.add_argument("-o", "--output", required=True, help="output MCAP file")
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
        "--mode", choices=("binary", "line"), help="wire mode (default: detect from the header)"
    )
    p.set_defaults(func=run)


def run(args):
    """Record until the stop condition, Ctrl-C or SIGTERM; report and choose the exit code."""
    from acquisition.progress import ProgressPrinter, describe
    from acquisition.recorder import Recorder
    from imu_square.log import logger
    from imu_square.program import read_program

    program = read_program(args.program)
    printer = ProgressPrinter(sys.stderr)
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
        progress=None if args.quiet else printer,
        header_timeout_s=args.header_timeout,
    )
    previous = {s: signal.signal(s, lambda *_: recorder.stop()) for s in _STOP_SIGNALS}
    logger.addFilter(printer)
    try:
        status = recorder.run()
    finally:
        logger.removeFilter(printer)
        printer.close()
        for s, handler in previous.items():
            signal.signal(s, handler)
    if status.samples_written == 0:
        raise AcquisitionError(
            f"recording stopped ({status.stop_reason}) before any sample was written; "
            f"no file at {args.output!r}"
        )
    print(f"{args.output}: {describe(status)}; stopped: {status.stop_reason}", file=sys.stderr)
    if not status.complete:
        print(f"{args.output}: incomplete recording (the file is valid)", file=sys.stderr)
        return EXIT_INCOMPLETE
    return 0


_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
