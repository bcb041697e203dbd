"""``imu-square init``: a commented monitor file and the units that run it every night."""

import shutil
import sys
from pathlib import Path

from imu_square.errors import ImuSquareError

HELP = "write a monitor file for a machine, and its nightly systemd units"


def register(sub):
    """Add the ``init`` subcommand."""
    p = sub.add_parser(
        "init",
        help=HELP,
        description="Write a commented monitor file (monitor.toml) for one machine, then print "
        "the systemd service and timer that run 'imu-square nightly --config FILE' every night "
        "at --at, and the equivalent crontab line. With --systemd DIR the units are written to "
        "DIR (for example ~/.config/systemd/user/ or /etc/systemd/system/).",
    )
    p.add_argument("--machine-id", required=True, help="the machine's name (letters, digits, _.-)")
    p.add_argument("-o", "--output", default="monitor.toml", help="monitor file to write")
    p.add_argument(
        "--port", default="emulated", help="the sensor board's serial port (default: emulated)"
    )
    p.add_argument("--history", default="", help="history file or postgresql:// URL")
    p.add_argument(
        "--program",
        metavar="PROGRAM.toml",
        help="the circle test the machine runs (default: the paper's test); the analysis "
        "settings a plan file (imu-square plan -o) carries come with it",
    )
    p.add_argument("--at", default="02:30", help="local time of the nightly run, HH:MM")
    p.add_argument("--user", help="account the systemd service runs as (a system unit)")
    p.add_argument("--systemd", metavar="DIR", help="write the service and timer into DIR")
    p.add_argument("--force", action="store_true", help="overwrite an existing monitor file")
    p.set_defaults(func=run)


def run(args):
    """Write the monitor file (validated by reading it back), print or write the units."""
    from imu_square.monitor.config import read_monitor
    from imu_square.monitor.schedule import check_time, cron_line, monitor_file_text, systemd_units

    try:
        check_time(args.at)
    except ValueError as exc:
        raise ImuSquareError(str(exc)) from None
    out = Path(args.output).expanduser().absolute()
    if out.exists() and not args.force:
        raise ImuSquareError(f"{out}: exists already; give --force to overwrite it")
    if args.systemd:  # checked first: a failure must not leave a monitor file behind
        from imu_square.monitor.publish import ensure_folder

        ensure_folder(Path(args.systemd).expanduser(), "systemd units")
    program, analysis = "", None
    if args.program:
        from imu_square.monitor.config import AnalysisSettings
        from imu_square.program import read_program

        given = Path(args.program).expanduser().absolute()
        if read_program(given).n_feeds > 1:
            raise ImuSquareError(
                f"{given}: runs several feeds; the monitor judges a one-feed test night to "
                "night (imu-square plan without --separate-gravity)"
            )
        analysis = AnalysisSettings.of_program_file(given)
        # Beside the monitor file it is named relative to it, as the monitor file reads it.
        program = str(given.relative_to(out.parent) if given.parent == out.parent else given)
    text = monitor_file_text(
        args.machine_id, port=args.port, history=args.history, program=program, analysis=analysis
    )
    tmp = out.with_name(f".{out.name}.tmp")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_text(text, encoding="utf-8")
        try:
            read_monitor(tmp)  # what it writes must read back: machine id, port, history
        except ImuSquareError as exc:
            tmp.unlink()
            raise ImuSquareError(str(exc).replace(str(tmp), str(out))) from None
        tmp.replace(out)
    except OSError as exc:
        raise ImuSquareError(f"{out}: cannot write the monitor file: {exc.strerror}") from None
    print(f"wrote {out}", file=sys.stderr)

    executable = shutil.which("imu-square") or str(Path(sys.argv[0]).absolute())
    units = systemd_units(args.machine_id, executable, out, at=args.at, user=args.user)
    if args.systemd:
        folder = Path(args.systemd).expanduser()
        try:
            folder.mkdir(parents=True, exist_ok=True)
            for name, body in units.items():
                (folder / name).write_text(body, encoding="utf-8")
        except OSError as exc:
            raise ImuSquareError(
                f"{folder}: cannot write the systemd units: {exc.strerror}"
            ) from None
        names = " ".join(units)
        print(f"wrote {names} into {folder}", file=sys.stderr)
        timer = next(n for n in units if n.endswith(".timer"))
        scope = "" if args.user else " --user"
        print(
            f"enable with: systemctl{scope} daemon-reload && systemctl{scope} enable --now {timer}",
            file=sys.stderr,
        )
    else:
        for name, body in units.items():
            print(f"# --- {name}\n{body}")
    log = out.with_name(f"{args.machine_id}.log")
    print(f"# --- or, in crontab -e:\n{cron_line(executable, out, at=args.at, log_file=log)}")
    return 0
