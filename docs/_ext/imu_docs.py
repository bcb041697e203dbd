"""Sphinx directives that generate the documentation from the code, so it cannot drift.

- ``file-fields``: the fields of a TOML file the tool reads (``monitor``,
  ``program``, ``machine``, ``sensor``), recorded while the tool's own reader
  reads a file: every :class:`imu_square.validation.TomlTable` it opens, with
  the fields it allows, and every field's check (kind, range, default). A
  field or a table added to a reader appears here with no edit of the docs.
- ``history-schema``: the tables of a fresh history, as the migrations create them.
- ``command-output``: runs an ``imu-square`` command at build time and shows
  what it printed; a command that exits otherwise than expected fails the build.

:func:`cli_parser` is the parser the CLI reference (sphinx-argparse) renders:
every command registered in full, the acquisition's commands included.
"""

import contextlib
import functools
import math
import os
import shlex
import sqlite3
import subprocess
import sys
import tempfile
from pathlib import Path

from docutils import nodes
from docutils.parsers.rst import Directive, directives

ROOT = Path(__file__).resolve().parents[2]


def cli_parser():
    """``imu-square``'s argument parser with every command registered in full."""
    from imu_square.cli import build_parser

    return build_parser(full=True)


# --- the TOML files' fields ----------------------------------------------------------------

_GETTERS = ("number", "numbers", "integer", "flag", "text", "choice", "choices", "env_name", "path")


@contextlib.contextmanager
def _recording_tables():
    """Record every TomlTable opened and every field checked while the block runs.

    Yields
    ------
    dict
        ``{table label: {"fields": [...], "checks": {field: (getter, args, kwargs)},
        "defaults": {...}}}``, filled as the readers run.
    """
    from imu_square import validation

    seen = {}
    cls = validation.TomlTable
    originals = {name: getattr(cls, name) for name in ("__init__", *_GETTERS)}

    def init(self, table, where, fields, *args, **kwargs):
        originals["__init__"](self, table, where, fields, *args, **kwargs)
        label = where.split(" #")[0]
        entry = seen.setdefault(label, {"fields": [], "checks": {}, "defaults": {}})
        entry["fields"] += [f for f in fields if f not in entry["fields"]]
        entry["defaults"].update(fields if isinstance(fields, dict) else {})

    def wrap(name):
        def getter(self, key, *args, **kwargs):
            label = self.where.split(" #")[0]
            checks = seen[label]["checks"]
            if key not in checks:
                checks[key] = (name, args, kwargs)
            return originals[name](self, key, *args, **kwargs)

        return getter

    try:
        cls.__init__ = init
        for name in _GETTERS:
            setattr(cls, name, wrap(name))
        yield seen
    finally:
        for name, method in originals.items():
            setattr(cls, name, method)


def _monitor_probe(folder):
    """A monitor file with every table, each alert sink once, read by the monitor's reader."""
    from imu_square.monitor.alerts.config import SINK_KINDS
    from imu_square.monitor.config import SECTIONS, monitor_from_mapping

    doc = {name: {} for name in SECTIONS}
    doc["monitor"] = {"machine_id": "mill-3"}
    doc["metrics"] = {"textfile": "mill-3.prom"}
    sinks = {
        "json_file": {"path": "latest-alert.json"},
        "webhook": {"url": "https://hooks.example.com/imu-square"},
        "email": {"host": "smtp.example.com", "sender": "a@example.com", "to": ["b@example.com"]},
    }
    doc["alerts"] = {"log": {}, **{kind: sinks.get(kind, {}) for kind in SINK_KINDS}}
    monitor_from_mapping(doc, Path(folder) / "monitor.toml")


def _read_file(kind):
    if kind == "monitor":
        with tempfile.TemporaryDirectory() as folder:
            _monitor_probe(folder)
        return
    from imu_square.program import read_program
    from imu_square.simulate import data_path, read_machine, read_sensor

    reader, name = {
        "program": (read_program, "program_paper.toml"),
        "machine": (read_machine, "machine_typical.toml"),
        "sensor": (read_sensor, "sensor_paper.toml"),
    }[kind]
    reader(data_path(name))


@functools.cache
def file_tables(kind):
    """The tables and fields of one kind of file, as its reader checks them.

    Parameters
    ----------
    kind : str
        ``"monitor"``, ``"program"``, ``"machine"`` or ``"sensor"``.

    Returns
    -------
    dict of str to list of (str, str, str)
        Each table's label (``"[alerts.email]"``) and its fields, each as
        ``(field, what is allowed, default)``, in the reader's order.
    """
    with _recording_tables() as seen:
        _read_file(kind)
    out = {}
    for label, entry in seen.items():
        rows = []
        for field in entry["fields"]:
            sub = f"[{label.strip('[]')}.{field}]"
            if sub in seen:
                rows.append((field, f"a table: {sub}", ""))
                continue
            check = entry["checks"].get(field)
            rows.append((field, *_describe(check, entry["defaults"], field)))
        out[label] = rows
    return out


def _describe(check, defaults, field):
    """What a field allows and its default, from the check its reader made."""
    from imu_square.validation import _REQUIRED, interval

    if check is None:  # checked by the reader's own code (or an old name, read with a warning)
        return "", _show(defaults.get(field, _REQUIRED))
    name, args, kwargs = check
    default = kwargs.get("default", defaults.get(field, _REQUIRED))
    if name in ("number", "integer", "numbers"):
        if name == "numbers":
            what, bounds = args[1], args[2:4]
        else:
            what, bounds = ("a number" if name == "number" else "a whole number"), args[:2]
        lo, hi = [*bounds, None, None][:2]
        lo, hi = kwargs.get("lo", lo), kwargs.get("hi", hi)
        if lo is not None or hi is not None:
            span = interval(lo, hi, kwargs.get("lo_open", False), kwargs.get("hi_open", False))
            what = f"{what} in {span}"
    elif name == "choice":
        what = "one of " + ", ".join(f"``{c}``" for c in args[0])
    elif name == "choices":
        what = "a list of " + ", ".join(f"``{c}``" for c in args[0])
    else:
        what = {
            "flag": "true or false",
            "text": "text" + (", may be empty" if kwargs.get("empty") else ""),
            "env_name": "the name of an environment variable",
            "path": "a path (relative: from the file's folder)",
        }[name]
    return what, _show(default)


def _show(default):
    from imu_square.validation import _REQUIRED

    if default is _REQUIRED:
        return "—"
    if default is None:
        return "unset"
    if isinstance(default, float) and math.isfinite(default):
        return f"``{default:g}``"
    if isinstance(default, str):
        return f'``"{default}"``'
    if isinstance(default, bool):
        return f"``{str(default).lower()}``"
    if isinstance(default, list | tuple):
        items = ", ".join(f'"{v}"' if isinstance(v, str) else f"{v}" for v in default)
        return f"``[{items}]``"
    return f"``{default}``"


def _cell(text):
    """A table cell's paragraph: ````literal```` spans as code, the rest as text."""
    para = nodes.paragraph()
    for i, part in enumerate(text.split("``")):
        if part:
            para += nodes.literal(part, part) if i % 2 else nodes.Text(part)
    return para


def _table(header, rows, widths=(25, 50, 25)):
    """A docutils table from text rows; built as nodes, so it renders in reST and MyST pages."""
    group = nodes.tgroup(cols=len(widths))
    group += [nodes.colspec(colwidth=w) for w in widths]

    def row(cells):
        out = nodes.row()
        for cell in cells:
            entry = nodes.entry()
            entry += _cell(cell or "")
            out += entry
        return out

    head, body = nodes.thead(), nodes.tbody()
    head += row(header)
    body += [row(r) for r in rows]
    group += [head, body]
    table = nodes.table()
    table += group
    return [table]


class FileFields(Directive):
    """``.. file-fields:: monitor``: one table per TOML table of that file."""

    required_arguments = 1

    def run(self):
        kind = self.arguments[0]
        out = []
        for label, rows in file_tables(kind).items():
            section = nodes.rubric(text=label)
            fields = [(f"``{field}``", what, default) for field, what, default in rows]
            out += [section, *_table(("field", "allowed", "default"), fields)]
        return out


# --- the history's schema ------------------------------------------------------------------


class HistorySchema(Directive):
    """``.. history-schema::``: the CREATE statements of a fresh SQLite history."""

    def run(self):
        from imu_square.monitor.history.store import open_history

        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / "history.db"
            open_history(str(path)).close()
            with contextlib.closing(sqlite3.connect(path)) as db:
                rows = db.execute(
                    "SELECT sql FROM sqlite_master WHERE sql IS NOT NULL "
                    "AND name NOT LIKE 'sqlite_%' ORDER BY type DESC, name"
                ).fetchall()
        text = ";\n\n".join(sql for (sql,) in rows) + ";"
        block = nodes.literal_block(text, text)
        block["language"] = "sql"
        return [block]


# --- a command's output, produced by the build ---------------------------------------------


def scratch_dir(app):
    """The folder commands run in: a clone's root as a user has it (its files linked)."""
    folder = Path(app.doctreedir).parent / "scratch"
    folder.mkdir(parents=True, exist_ok=True)
    for name in ("imu_square", "recordings"):
        link = folder / name
        if not link.exists():
            link.symlink_to(ROOT / name)
    return folder


def _as_shop(text, app):
    """The build's folders in a command's output as a shop's computer would show them."""
    text = text.replace(str(Path(sys.executable).parent), "/home/shop/imu-square/.venv/bin")
    return text.replace(str(scratch_dir(app)), "/home/shop")


class CommandOutput(Directive):
    """``.. command-output:: imu-square plan ...``: the command and what it printed.

    Options: ``:returncode:`` (expected, default 0), ``:stdout-only:`` (leave
    stderr out), ``:hide-command:``, ``:hide-output:``, ``:show-file: NAME``
    (then show the file the command wrote, as TOML when its name ends so).
    The build's own folders are shown as a shop's: the folder the command ran
    in as ``/home/shop``, the interpreter's as ``/home/shop/imu-square/.venv/bin``.
    """

    required_arguments = 1
    final_argument_whitespace = True
    option_spec = {  # noqa: RUF012 -- docutils' own class attribute
        "returncode": directives.nonnegative_int,
        "stdout-only": directives.flag,
        "hide-command": directives.flag,
        "hide-output": directives.flag,
        "show-file": directives.unchanged,
    }

    def run(self):
        env = self.state.document.settings.env
        command = " ".join(self.arguments[0].split())
        argv = shlex.split(command)
        bindir = Path(sys.executable).parent
        if argv[0] == "imu-square":
            # the installed command, as a shop runs it (init writes its path into the units)
            script = bindir / "imu-square"
            head = [str(script)] if script.exists() else [sys.executable, "-m", "imu_square.cli"]
            argv = [*head, *argv[1:]]
        expected = self.options.get("returncode", 0)
        done = subprocess.run(
            argv,
            cwd=scratch_dir(env.app),
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL if "stdout-only" in self.options else subprocess.STDOUT,
            text=True,
            env={
                **os.environ,
                "COLUMNS": "100",
                "PATH": f"{bindir}{os.pathsep}{os.environ['PATH']}",
            },
            timeout=600,
        )
        if done.returncode != expected:
            raise self.error(
                f"'{command}' exited {done.returncode}, expected {expected}:\n{done.stdout}"
            )
        text = "" if "hide-output" in self.options else _as_shop(done.stdout.rstrip(), env.app)
        if "hide-command" not in self.options:
            text = f"$ {command}\n{text}"
        block = nodes.literal_block(text, text)
        block["language"] = "text"
        out = [block] if text else []
        if "show-file" in self.options:
            name = self.options["show-file"]
            content = (scratch_dir(env.app) / name).read_text(encoding="utf-8").rstrip()
            content = _as_shop(content, env.app)
            shown = nodes.literal_block(content, content)
            shown["language"] = "toml" if name.endswith(".toml") else "text"
            out.append(shown)
        return out


def setup(app):
    """Register the directives."""
    app.add_directive("file-fields", FileFields)
    app.add_directive("history-schema", HistorySchema)
    app.add_directive("command-output", CommandOutput)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
