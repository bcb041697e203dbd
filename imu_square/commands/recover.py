"""``imu-square recover``: rewrite what is complete in a cut MCAP recording."""

import sys

from imu_square.io.mcap import recover_mcap


def register(sub):
    """Add the ``recover`` subcommand."""
    p = sub.add_parser(
        "recover",
        help="rescue the complete part of a cut or damaged MCAP recording",
        description="Read a cut or damaged MCAP recording from the start, keep every complete "
        "chunk, and write it as a whole file with indexes.",
    )
    p.add_argument("recording", help="damaged MCAP file")
    p.add_argument("-o", "--output", required=True, help="repaired MCAP file to write")
    p.set_defaults(func=run)


def run(args):
    """Recover the recording and say what was saved."""
    r = recover_mcap(args.recording, args.output)
    state = (
        "the file was complete"
        if r.complete
        else f"the file was cut at byte {r.cut_at_byte} of {r.file_bytes}, "
        f"after time {r.last_time_ns * 1e-9:.3f} s"
    )
    print(
        f"recovered {r.samples} samples ({r.duration_s:.3f} s) and {r.events} events; "
        f"{state}; wrote {args.output}",
        file=sys.stderr,
    )
    return 0
