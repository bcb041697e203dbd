"""Start-up pays only for the command run: no matplotlib, scipy.optimize or acquisition
unless that command needs them (issue 10: 0.8 s of CPU and 75 MiB for every command before)."""

import importlib
import json
import subprocess
import sys

import pytest

from imu_square.cli import build_parser, command_help, commands, main

HEAVY = ("matplotlib", "scipy.optimize", "acquisition")
# what each command may pull in at start-up, because registering it needs it
ALLOWED = {"reference": {"scipy.optimize"}, "compare": {"scipy.optimize"}}
ACQUISITION = {"record", "emulate", "nightly"}

PROBE = """
import json, sys
from imu_square.cli import build_parser
build_parser(only=sys.argv[1])
heavy = sorted({h for h in HEAVY for m in sys.modules if m == h or m.startswith(h + ".")})
print(json.dumps(heavy))
""".replace("HEAVY", repr(HEAVY))


def test_every_command_is_found_without_importing_it():
    names = commands()
    assert {"analyze", "import", "nightly", "record", "history", "baseline", "init"} <= set(names)
    assert names["import"] == "imu_square.commands.import_"
    assert names["nightly"] == "acquisition.commands.nightly"


@pytest.mark.parametrize("name", sorted(commands()))
def test_a_command_imports_only_what_it_needs(name):
    out = subprocess.run(
        [sys.executable, "-c", PROBE, name], capture_output=True, text=True, check=True
    ).stdout
    heavy = set(json.loads(out))
    allowed = ALLOWED.get(name, set()) | ({"acquisition"} if name in ACQUISITION else set())
    assert heavy <= allowed, f"{name} imports {sorted(heavy - allowed)} at start-up"


def test_importing_the_package_is_light():
    out = subprocess.run(
        [sys.executable, "-c", "import imu_square, sys; print(sorted(sys.modules))"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert "numpy" not in out and "matplotlib" not in out and "acquisition" not in out


LISTING = """
import contextlib, io, json, sys
from imu_square.cli import main
out = io.StringIO()
with contextlib.redirect_stdout(out):
    try:
        main(["--help"])
    except SystemExit as exc:
        code = exc.code
loaded = sorted(m for m in sys.modules if m.split(".")[0] in ("numpy", "scipy", "matplotlib",
                "acquisition") or m.startswith("imu_square.commands."))
print(json.dumps({"code": code, "help": out.getvalue(), "loaded": loaded}))
"""


def test_the_command_listing_imports_no_command():
    got = json.loads(
        subprocess.run(
            [sys.executable, "-c", LISTING], capture_output=True, text=True, check=True
        ).stdout
    )
    assert got["code"] == 0
    assert got["loaded"] == [], f"`imu-square --help` imported {got['loaded']}"
    listed = " ".join(got["help"].split())
    for name in commands():
        assert f" {name} " in listed, f"{name} missing from the listing"


@pytest.mark.parametrize("name", sorted(commands()))
def test_the_listing_shows_what_the_command_registers(name):
    """The help read from the source is the one the command's own parser carries."""
    module = commands()[name]
    listed = command_help(module)
    parser = build_parser(only=name)
    sub = next(a for a in parser._actions if a.dest == "command")
    registered = next(c.help for c in sub._choices_actions if c.dest == name)
    assert listed == registered == importlib.import_module(module).HELP
    assert listed and "\n" not in listed


def _install_plugin(root, dist, modules, commands_):
    """A real installed distribution: its modules and an imu_square.commands entry point each."""
    for relative, text in modules.items():
        path = root / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    info = root / f"{dist}-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 1.0\n")
    lines = "".join(f"{name} = {module}\n" for name, module in commands_.items())
    (info / "entry_points.txt").write_text(f"[imu_square.commands]\n{lines}")


def test_a_plugin_without_help_or_of_one_file_is_listed(tmp_path, monkeypatch, capsys):
    # A plugin written when register() was all a command needed has no HELP; one of a
    # single file has no package to look in. `imu-square --help` crashed on either.
    register = (
        "def register(sub):\n"
        "    p = sub.add_parser({name!r}, help={summary!r})\n"
        "    p.set_defaults(func=lambda args: 0)\n"
    )
    _install_plugin(
        tmp_path,
        "oldplug",
        {
            "oldplug/__init__.py": "",
            "oldplug/cmd.py": register.format(name="oldcmd", summary="a plugin without HELP"),
            "oneplug.py": 'HELP = "a plugin of one file"\n'
            + register.format(name="onecmd", summary="a plugin of one file"),
        },
        {"oldcmd": "oldplug.cmd", "onecmd": "oneplug"},
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    listed = " ".join(capsys.readouterr().out.split())
    assert "oldcmd a plugin without HELP" in listed and "onecmd a plugin of one file" in listed
    assert "analyze squareness from recorded runs" in listed
    assert main(["-v"]) == 2 and "oldcmd" in capsys.readouterr().err
    assert main(["oldcmd"]) == 0 and main(["onecmd"]) == 0


def test_help_before_a_command_lists_every_command(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["-h", "analyze"])
    assert exc.value.code == 0
    listed = " ".join(capsys.readouterr().out.split())
    assert all(f" {name} " in listed for name in commands())
