"""Where a command's result goes: stdout, unless ``--json`` puts the JSON there."""

import sys


def result_stream(args):
    """The stream for a command's result for a person.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed arguments; ``args.json`` when the command has ``--json``.

    Returns
    -------
    file
        stdout; stderr when ``--json`` writes the machine-readable result to
        stdout, so that the two never mix.
    """
    return sys.stderr if getattr(args, "json", False) else sys.stdout
