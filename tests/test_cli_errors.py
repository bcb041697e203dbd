"""Every command on bad input: one line on stderr, the file named exactly once, no traceback.

Readers put the path in their message; the CLI prints the message as it is; the
pipeline names no file and its caller adds it (docs/model.md, STYLE 7).
"""

import subprocess
import sys
from pathlib import Path

import numpy as np

from imu_square.cli import main
from imu_square.io.mcap import RecordingWriter

ROOT = Path(__file__).resolve().parents[1]
GOOD_RECORDING = ROOT / "recordings" / "square_20um.mcap"
GOOD_PROGRAM = ROOT / "imu_square" / "data" / "program_paper.toml"


class _BadProgram:
    """Writes a program attachment that is valid TOML but not a valid program."""

    def to_toml(self):
        return "[program]\nradius_mm = -5\nfeed_mm_per_min = 6000\ncycles_per_direction = 15\n"


def _bad_files(folder):
    f = {}
    f["empty.mcap"] = folder / "empty.mcap"
    f["empty.mcap"].write_bytes(b"")
    f["junk.mcap"] = folder / "junk.mcap"
    f["junk.mcap"].write_bytes(b"hello, not a recording\n")
    f["cut.mcap"] = folder / "cut.mcap"
    f["cut.mcap"].write_bytes(GOOD_RECORDING.read_bytes()[:200_000])
    f["badprog.mcap"] = folder / "badprog.mcap"
    f["rest.mcap"] = folder / "rest.mcap"  # a valid file in which nothing moves
    for name, program in (("badprog.mcap", _BadProgram()), ("rest.mcap", None)):
        with RecordingWriter(f[name], dt_ns=2_000_000, program=program) as w:
            n = 20_000
            w.write_samples(
                np.arange(n), 10**9 + 2_000_000 * np.arange(n), np.tile([0.0, 0.0, 9.81], (n, 1))
            )
    f["badprog.toml"] = folder / "badprog.toml"
    f["badprog.toml"].write_text(
        "[program]\nradius_mm = -1\nfeed_mm_per_min = 6000\ncycles_per_direction = 15\n"
    )
    f["notoml.toml"] = folder / "notoml.toml"
    f["notoml.toml"].write_text("[program\nradius_mm = 1\n")
    f["badmachine.toml"] = folder / "badmachine.toml"
    f["badmachine.toml"].write_text('[geometry]\nmachine_squareness_um_per_m = "x"\n')
    f["badsensor.toml"] = folder / "badsensor.toml"
    f["badsensor.toml"].write_text("[sensor]\nnoise_density_ug_rthz = -3\n")
    f["mm.csv"] = folder / "mm.csv"  # Klipper units given as the default layout
    rows = [f"{k * 0.001:.3f},1.0,2.0,9806.65" for k in range(2000)]
    f["mm.csv"].write_text("time_s,accel_x,accel_y,accel_z\n" + "\n".join(rows) + "\n")
    f["missing.mcap"] = folder / "missing.mcap"
    return f


CASES = [
    ("analyze", "empty.mcap", ["analyze", "{empty.mcap}"]),
    ("analyze", "junk.mcap", ["analyze", "{junk.mcap}"]),
    ("analyze", "missing.mcap", ["analyze", "{missing.mcap}"]),
    ("analyze", "badprog.mcap", ["analyze", "{badprog.mcap}"]),
    ("analyze", "rest.mcap", ["analyze", "{rest.mcap}", "--program", str(GOOD_PROGRAM)]),
    ("analyze", "badprog.toml", ["analyze", str(GOOD_RECORDING), "--program", "{badprog.toml}"]),
    ("info", "empty.mcap", ["info", "{empty.mcap}"]),
    ("info", "junk.mcap", ["info", "{junk.mcap}"]),
    ("info", "badprog.mcap", ["info", "{badprog.mcap}"]),
    ("recover", "junk.mcap", ["recover", "{junk.mcap}", "-o", "{out}"]),
    ("program", "badprog.toml", ["program", "{badprog.toml}"]),
    ("program", "notoml.toml", ["program", "{notoml.toml}"]),
    ("simulate", "badprog.toml", ["simulate", "-o", "{out}", "--program", "{badprog.toml}"]),
    ("simulate", "badmachine.toml", ["simulate", "-o", "{out}", "--machine", "{badmachine.toml}"]),
    ("simulate", "badsensor.toml", ["simulate", "-o", "{out}", "--sensor", "{badsensor.toml}"]),
    ("reference", "badmachine.toml", ["reference", "--machine", "{badmachine.toml}"]),
    ("import", "mm.csv", ["import", "{mm.csv}", "--program", str(GOOD_PROGRAM), "-o", "{out}"]),
    (
        "import",
        "badprog.toml",
        ["import", "{mm.csv}", "--program", "{badprog.toml}", "-o", "{out}"],
    ),
    ("emulate", "badprog.toml", ["emulate", "--program", "{badprog.toml}", "--link", "{link}"]),
    ("nightly", "badprog.toml", ["nightly", "--program", "{badprog.toml}", "--out", "{outdir}"]),
    (
        "nightly",
        "badmachine.toml",
        ["nightly", "--machine", "{badmachine.toml}", "--out", "{outdir}"],
    ),
]


def test_every_command_names_the_bad_file_once(tmp_path, capsys):
    files = _bad_files(tmp_path)
    names = {k: str(v) for k, v in files.items()}
    names.update(out=str(tmp_path / "o.mcap"), link=str(tmp_path / "link"), outdir=str(tmp_path))
    failures = []
    for command, bad, argv in CASES:
        args = [names[a[1:-1]] if a.startswith("{") else a for a in argv]
        code = main(args)  # an exception main does not turn into one line fails the test
        err = capsys.readouterr().err
        errors = [ln for ln in err.splitlines() if ln.startswith("imu-square ")]
        problem = None
        if code == 0:
            problem = "exit 0"
        elif len(errors) != 1 or not errors[0].startswith(f"imu-square {command}: error: "):
            problem = f"not one error line: {err!r}"
        elif errors[0].count(bad) != 1:
            problem = f"{bad} named {errors[0].count(bad)} times: {errors[0]!r}"
        if problem:
            failures.append(f"{command} {bad}: {problem}")
    assert not failures, "\n".join(failures)


def test_the_installed_script_prints_no_traceback(tmp_path):
    files = _bad_files(tmp_path)
    script = Path(sys.executable).with_name("imu-square")
    proc = subprocess.run(
        [str(script), "analyze", str(files["badprog.mcap"])],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2
    assert proc.stderr.count(str(files["badprog.mcap"])) == 1
    assert "Traceback" not in proc.stderr


def test_history_refuses_a_plot_it_cannot_write_before_opening_the_history(tmp_path, capsys):
    config = tmp_path / "monitor.toml"  # never read: the plot is checked first
    assert main(["history", "--config", str(config), "--plot", str(tmp_path / "trend.txt")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "plot format (suffix)" in err[0] and "'txt'" in err[0]
    assert not (tmp_path / "trend.txt").exists() and not config.exists()
