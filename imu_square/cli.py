"""The ``imu-square`` command: parses arguments and calls library functions.

Subcommands are the modules of :mod:`imu_square.commands`, plus the modules of
any package registered under the ``imu_square.commands`` entry-point group
(the ``acquisition`` package registers its own that way, so the library never
imports it). Each module defines ``HELP``, its one-line summary as a string
literal, and ``register(subparsers)``, which adds one parser (with that help)
whose ``func`` default takes the parsed arguments and returns an exit code.
``imu-square --help`` reads every ``HELP`` from the modules' source without
importing them, so that listing the commands costs no command's imports (a
plugin's module without a literal ``HELP`` is imported and registered instead).

A command's result goes to stdout: a table or a verdict for a person, or JSON
with ``--json`` (the person's text then on stderr); progress, warnings and
errors go to stderr, whether or not a terminal is attached.
A user's mistake is one line on stderr and a non-zero exit, never a traceback.

Exit codes shared by every command: 0 done; 2 a user's mistake (bad option,
bad or missing input, an output that cannot be written), or a recording that
cannot be analysed; 3 incomplete (a recording with missing data, a cut file;
what there is remains valid); 4 writing an output failed part-way (disk full,
I/O error), what was flushed before is kept; 130 interrupted.
"""

import argparse
import ast
import importlib
import importlib.util
import logging
import os
import pkgutil
import sys
import warnings
from importlib.metadata import entry_points
from pathlib import Path

from imu_square import __version__
from imu_square.errors import ImuSquareError, OutputWriteError

EXIT_OK = 0
EXIT_USER_ERROR = 2
EXIT_INCOMPLETE = 3
EXIT_WRITE_FAILED = 4
EXIT_INTERRUPTED = 130


def commands():
    """Every subcommand's name and module, without importing any command module.

    Returns
    -------
    dict of str to str
        ``{name: module}``, sorted by name: this package's ``commands`` modules
        (``import_`` is ``import``) and the ``imu_square.commands`` entry points,
        one per command, by which other packages (``acquisition``) add theirs.
    """
    out = {}
    package = importlib.import_module("imu_square.commands")
    for info in pkgutil.iter_modules(package.__path__):
        if not info.name.startswith("_"):
            out[info.name.rstrip("_")] = f"{package.__name__}.{info.name}"
    for ep in entry_points(group="imu_square.commands"):
        out[ep.name] = ep.value
    return dict(sorted(out.items()))


def build_parser(only=None, full=False):
    """The argument parser: every subcommand listed, or ``only`` registered in full.

    Parameters
    ----------
    only : str, optional
        The one command to register (and so to import): a command pays only
        for its own imports at start-up. Without it, every command is listed
        by its ``HELP`` alone, none imported: the parser of ``imu-square --help``.
    full : bool
        Register every command in full, importing them all: the parser the
        documentation's CLI reference is generated from.

    Returns
    -------
    argparse.ArgumentParser
    """
    parser = argparse.ArgumentParser(
        prog="imu-square",
        description="Machine-tool squareness from a table-mounted accelerometer.",
        epilog="Exit codes: 0 done; 2 a user's mistake or an input that cannot be used, in "
        "one line; 3 incomplete (a cut file, a recording with data missing: what there is "
        "stays valid); 4 writing an output failed part-way (disk full); 130 interrupted. "
        "Each command's --help says which apply.",
    )
    parser.add_argument("--version", action="version", version=f"imu-square {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more status output")
    parser.add_argument("-q", "--quiet", action="store_true", help="errors only")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, module in commands().items():
        if full:
            importlib.import_module(module).register(sub)
        elif only is None:
            try:
                summary = command_help(module)
            except (LookupError, OSError, SyntaxError, ValueError):
                # A plugin's module without a literal HELP (written when register() was
                # all a command needed): registered in full, its imports paid, as before.
                importlib.import_module(module).register(sub)
                continue
            sub.add_parser(name, help=summary, add_help=False)
        elif name == only:
            importlib.import_module(module).register(sub)
    return parser


def command_help(module):
    """A command module's ``HELP``, read from its source without importing it.

    Parameters
    ----------
    module : str
        Dotted name of the command module.

    Returns
    -------
    str
        The one-line summary that ``imu-square --help`` lists.
    """
    tree = ast.parse(_module_source(module).read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, ast.Assign) and [getattr(t, "id", None) for t in node.targets] == [
            "HELP"
        ]:
            return ast.literal_eval(node.value)
    raise LookupError(f"command module {module} defines no HELP string")


def _module_source(module):
    """Path of a module's source file, found without importing the module or its packages
    (``importlib.util.find_spec`` would import ``acquisition`` for its commands)."""
    top, *rest = module.split(".")
    spec = importlib.util.find_spec(top)
    if not rest:  # a top-level module (a plugin of one file, or a package's __init__)
        return Path(spec.origin)
    where = Path(next(iter(spec.submodule_search_locations)))
    for part in rest[:-1]:
        where = where / part
    leaf = where / rest[-1]
    return leaf / "__init__.py" if leaf.is_dir() else leaf.with_suffix(".py")


def _show_warning(message, category, filename, lineno, file=None, line=None):
    print(f"imu-square: warning: {message}", file=sys.stderr)


def main(argv=None):
    """Run the CLI.

    Parameters
    ----------
    argv : list of str, optional
        Arguments without the program name; ``sys.argv[1:]`` by default.

    Returns
    -------
    int
        The exit code.
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    named = next((a for a in argv if not a.startswith("-")), None)
    before = argv[: argv.index(named)] if named is not None else argv
    if {"-h", "--help"} & set(before):  # `imu-square -h analyze`: the top-level help, whole
        named = None
    parser = build_parser(only=named if named in commands() else None)
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help(sys.stderr)
        return EXIT_USER_ERROR
    level = logging.WARNING if args.quiet else (logging.DEBUG if args.verbose > 1 else logging.INFO)
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(message)s"))
    log = logging.getLogger("imu_square")
    log.handlers = [h for h in log.handlers if isinstance(h, logging.NullHandler)] + [handler]
    log.setLevel(level)
    with warnings.catch_warnings():
        warnings.showwarning = _show_warning
        try:
            return int(args.func(args) or EXIT_OK)
        except OutputWriteError as exc:
            print(f"imu-square {args.command}: error: {exc}", file=sys.stderr)
            return EXIT_WRITE_FAILED
        except ImuSquareError as exc:
            print(f"imu-square {args.command}: error: {exc}", file=sys.stderr)
            return EXIT_USER_ERROR
        except KeyboardInterrupt:
            print(f"imu-square {args.command}: interrupted", file=sys.stderr)
            return EXIT_INTERRUPTED
        except BrokenPipeError:
            # stdout went to a pipe that closed early (`... | head`): not an error of ours.
            sys.stdout = open(os.devnull, "w")  # keeps the interpreter's exit flush quiet
            return EXIT_OK
        finally:
            log.removeHandler(handler)


if __name__ == "__main__":
    sys.exit(main())
