"""``imu-square program``: validate a program and write the NC code for it."""

import sys
from pathlib import Path

from imu_square.errors import ProgramError
from imu_square.program import read_program
from imu_square.program.ncgen import DIALECTS, generate_nc

HELP = "validate a test program and write its NC code"


def register(sub):
    """Add the ``program`` subcommand."""
    p = sub.add_parser(
        "program",
        help=HELP,
        description="Validate PROGRAM.toml, print its nominal timing and, with -o, write the "
        "warm-up cycle as NC code for the chosen control.",
    )
    p.add_argument("program", help="program TOML file")
    p.add_argument(
        "--dialect", choices=DIALECTS, default="linuxcnc", help="control dialect (linuxcnc)"
    )
    p.add_argument("-o", "--output", help="NC file to write (e.g. warmup.nc)")
    p.add_argument(
        "--marker-mcode",
        type=int,
        metavar="N",
        help="user M-code written at the start and end of every block, for a trigger",
    )
    p.add_argument(
        "--feed-override-safe",
        action="store_true",
        help="lock the feed override at 100%% during the blocks (linuxcnc: M50 P0)",
    )
    p.set_defaults(func=run)


def run(args):
    """Validate the program, print its nominal timing and write the NC code."""
    prog = read_program(args.program)
    if prog.n_feeds == 1:
        print(
            f"{args.program}: r={prog.radius_m * 1e3:g} mm, v={prog.feed_m_per_s * 6e4:g} mm/min, "
            f"period {prog.period_s:.3f} s, {prog.n_blocks} blocks of "
            f"{prog.block_duration_s:.2f} s, {prog.duration_s:.1f} s",
            file=sys.stdout,
        )
    else:
        print(
            f"{args.program}: r={prog.radius_m * 1e3:g} mm, {prog.n_feeds} feeds, "
            f"{prog.n_blocks} blocks, {prog.duration_s:.1f} s",
            file=sys.stdout,
        )
        for f in range(prog.n_feeds):
            sub = prog.at_feed(f)
            print(
                f"  {sub.feed_m_per_s * 6e4:g} mm/min: period {sub.period_s:.3f} s, "
                f"{sub.n_blocks} blocks of {sub.block_duration_s:.2f} s, "
                f"v^2/r {sub.centripetal_m_s2:.3g} m/s^2",
                file=sys.stdout,
            )
    if args.output is None:
        return 0
    text = generate_nc(
        prog,
        args.dialect,
        marker_mcode=args.marker_mcode,
        feed_override_safe=args.feed_override_safe,
    )
    out = Path(args.output)
    try:
        out.write_text(text, encoding="ascii")
    except OSError as exc:
        raise ProgramError(f"{out}: cannot write the NC file: {exc}") from None
    print(f"wrote {out} ({args.dialect}, {text.count(chr(10))} lines)", file=sys.stderr)
    return 0
