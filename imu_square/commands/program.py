"""``imu-square program``: validate a program and write the NC code for it."""

from imu_square.program import read_program


def register(sub):
    """Add the ``program`` subcommand."""
    p = sub.add_parser("program", help="validate a test program and write its NC code")
    p.add_argument("program", help="program TOML file")
    p.set_defaults(func=run)


def run(args):
    """Validate the program and print its nominal timing."""
    import sys

    prog = read_program(args.program)
    print(
        f"{args.program}: r={prog.radius_m * 1e3:g} mm, v={prog.feed_m_per_s * 6e4:g} mm/min, "
        f"period {prog.period_s:.3f} s, {prog.n_blocks} blocks, {prog.duration_s:.1f} s",
        file=sys.stderr,
    )
    return 0
