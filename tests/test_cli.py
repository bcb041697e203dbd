"""The CLI's contract: subcommands are discovered, errors are one line, no traceback."""

import subprocess
import sys

import pytest

from imu_square.cli import build_parser, main


def test_every_subcommand_is_registered():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    assert {"program", "simulate", "import", "info", "recover", "reference", "analyze"} <= set(
        sub.choices
    )
    assert {"record", "emulate", "nightly"} <= set(sub.choices)


def test_no_command_prints_help_and_fails(capsys):
    assert main([]) == 2
    assert "usage: imu-square" in capsys.readouterr().err


def test_user_error_is_one_line_without_traceback(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[program]\nradius_mm = 0\nfeed_mm_per_min = 6000\ncycles_per_direction = 15\n")
    proc = subprocess.run(
        [sys.executable, "-m", "imu_square.cli", "program", str(bad)],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "radius_mm" in lines[0] and "got 0.0" in lines[0]
    assert "Traceback" not in proc.stderr


@pytest.mark.parametrize("argv", [["--version"]])
def test_version(argv, capsys):
    with pytest.raises(SystemExit, match="0"):
        main(argv)
    assert capsys.readouterr().out.startswith("imu-square ")
