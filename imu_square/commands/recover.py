"""``imu-square recover``: rewrite what is complete in a cut MCAP recording."""

import sys
from pathlib import Path

from imu_square.errors import OutputError
from imu_square.io.mcap import recover_mcap
from imu_square.io.output import check_output_path

HELP = "rescue the complete part of a cut or damaged MCAP recording"


def register(sub):
    """Add the ``recover`` subcommand."""
    p = sub.add_parser(
        "recover",
        help=HELP,
        description="Read a cut or damaged MCAP recording from the start, keep every complete "
        "chunk, and write it as a whole file with indexes. Exit codes: 0 written; 2 nothing "
        "recoverable, or the output cannot be written there (checked first: its folder must "
        "exist, and it must not be the damaged file itself); 4 writing failed part-way (disk "
        "full): the partial output is removed.",
    )
    p.add_argument("recording", help="damaged MCAP file")
    p.add_argument("-o", "--output", required=True, help="repaired MCAP file to write")
    p.set_defaults(func=run)


def run(args):
    """Recover the recording and say what was saved."""
    output = check_output_path(args.output, overwrite=True)
    source = Path(args.recording)
    if source.exists() and output.exists() and output.samefile(source):
        raise OutputError(
            f"{output}: is the damaged file itself; write the repaired file elsewhere, so the "
            f"original survives if writing fails"
        )
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
        file=sys.stdout,
    )
    return 0
