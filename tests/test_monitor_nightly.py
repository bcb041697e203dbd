"""The monitor end to end through the CLI: real recordings, a real SQLite history.

A low-noise sensor (0.5 µg/√Hz at 500 Hz) on a short brisk program (r = 25 mm
at 9000 mm/min, 5 cycles each way) makes one night's sigma about 2.5 µm/m, so
a 10 µm/m degradation is four sigma: the designed charts must find it within
a few nights, and a clean sequence must raise no alarm. The baseline and its
alarm design (the slow part) are made once and copied into each test.
"""

import json
import math
import shutil
import subprocess
import sys
from dataclasses import replace
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest

from imu_square.cli import main
from imu_square.io.mcap import write_mcap
from imu_square.monitor.schedule import EXIT_CODES
from imu_square.monitor.store import open_history
from imu_square.program import program_from_mapping
from imu_square.simulate.geometry import Geometry
from imu_square.simulate.machine import MachineModel
from imu_square.simulate.run import simulate_run
from imu_square.simulate.sensor import SensorModel

PROGRAM = program_from_mapping(
    {
        "radius_mm": 25.0,
        "feed_mm_per_min": 9000.0,
        "cycles_per_direction": 5,
        "dwell_s": 0.5,
    }
)
SENSOR = SensorModel(
    sample_rate_hz=500.0,
    noise_density_m_s2_rthz=0.5e-6 * 9.80665,
    eps_c_rad=math.radians(2.1),
    beta_rad=40e-6,
)
ALPHA = 20e-6
START = datetime(2026, 9, 1, 2, 30, tzinfo=UTC)
MONITOR = """\
[monitor]
machine_id = "m1"
history = "history.db"
data_dir = "data"

[program]
file = "{program}"

[analysis]
bootstrap = 0

[alarms]
false_alarm_nights = 730
step_um_per_m = 10.0
monte_carlo_nights = 200000

[alerts.json_file]
path = "data/alert.json"
states = ["ok", "warning", "alarm", "invalid", "stale_baseline", "no_baseline"]
"""


def night(folder, day, alpha=ALPHA, sensor=SENSOR, seed=None):
    """Simulate one night's recording into ``folder``; return its path."""
    machine = MachineModel(
        geometry=Geometry(machine_squareness_rad=alpha), tau_x_s=2e-3, tau_y_s=2.5e-3
    )
    when = START + timedelta(days=day)
    rec, _ = simulate_run(
        PROGRAM,
        machine,
        sensor,
        seed=1000 + day if seed is None else seed,
        t0_ns=int(when.timestamp() * 1e9),
        lead_in_s=1.0,
        lead_out_s=1.0,
    )
    path = folder / f"night-{day:03d}.mcap"
    write_mcap(rec, path)
    return path


def judge(config, path, capsys):
    """``imu-square nightly --config C --recording P --json``: exit code and record."""
    code = main(["nightly", "--config", str(config), "--recording", str(path), "--json"])
    out = capsys.readouterr().out
    return code, json.loads(out.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """A monitor folder with a history holding a 5-night baseline and its alarm design."""
    folder = tmp_path_factory.mktemp("monitor")
    (folder / "program.toml").write_text(PROGRAM.to_toml())
    (folder / "monitor.toml").write_text(MONITOR.format(program=folder / "program.toml"))
    runs = [str(night(folder, d)) for d in range(5)]
    assert main(["baseline", "set", "--config", str(folder / "monitor.toml"), *runs]) == 0
    return folder


@pytest.fixture
def rig(base, tmp_path):
    """A copy of the baseline's monitor folder for one test."""
    for name in ("program.toml", "monitor.toml"):
        shutil.copy(base / name, tmp_path / name)
    with open_history(base / "history.db") as h:
        h.backup(tmp_path / "history.db")
    return tmp_path


@pytest.mark.slow
def test_clean_nights_raise_no_alarm_and_a_10um_degradation_does(rig, capsys):
    config = rig / "monitor.toml"
    states = []
    for day in range(5, 13):
        code, record = judge(config, night(rig, day), capsys)
        assert code == EXIT_CODES[record["state"]]
        states.append(record["state"])
        # the change is the machine's: nothing has changed, within the stated u
        assert abs(record["change_urad"]) < 4 * record["u_change_urad"]
    assert "alarm" not in states, states
    fired = None
    for day in range(13, 19):
        code, record = judge(config, night(rig, day, alpha=ALPHA + 10e-6), capsys)
        if record["state"] == "alarm":
            fired = day
            assert code == EXIT_CODES["alarm"] == 11
            assert "check the machine" in record["verdict"]
            # the change seen is the 10 µm/m put in, within its uncertainty
            assert record["change_urad"] == pytest.approx(10.0, abs=4 * record["u_change_urad"])
            break
    assert fired is not None and fired <= 16, "a 4-sigma step must be found within 4 nights"
    # the alert sink got the night's record
    alert = json.loads((rig / "data" / "alert.json").read_text())
    assert alert["state"] == "alarm" and alert["machine_id"] == "m1"
    # the alarm stands until a new baseline is set
    code, record = judge(config, night(rig, 19, alpha=ALPHA + 10e-6), capsys)
    assert record["state"] == "alarm" and "until a new baseline" in record["verdict"]


@pytest.mark.slow
def test_a_remount_makes_the_baseline_stale_never_an_alarm(rig, capsys):
    config = rig / "monitor.toml"
    turned = replace(SENSOR, eps_c_rad=SENSOR.eps_c_rad + math.radians(1.5), beta_rad=900e-6)
    code, record = judge(config, night(rig, 5, sensor=turned), capsys)
    # beta moved by 860 µrad: as a change it would be a huge alarm
    assert record["state"] == "stale_baseline" and code == EXIT_CODES["stale_baseline"] == 13
    assert "remounted" in record["verdict"] and "set a new baseline" in record["verdict"]
    code, record = judge(config, night(rig, 6, sensor=turned), capsys)
    assert record["state"] == "stale_baseline"
    with open_history(rig / "history.db") as h:
        baseline = h.current_baseline("m1")
        assert baseline.stale and "remounted" in baseline.stale_reason
    # a new baseline from three nights of the new mounting clears it
    runs = [str(night(rig, d, sensor=turned)) for d in (7, 8, 9)]
    assert main(["baseline", "set", "--config", str(config), *runs]) == 0
    code, record = judge(config, night(rig, 10, sensor=turned), capsys)
    assert record["state"] in ("ok", "warning") and abs(record["change_urad"]) < 15


@pytest.mark.slow
def test_bad_recordings_are_invalid_and_never_move_the_charts(rig, capsys):
    config = rig / "monitor.toml"
    junk = rig / "junk.mcap"
    junk.write_bytes(b"\x89MCAP0\r\n" + b"\x00" * 100)
    still = night(rig, 6, alpha=ALPHA)
    # A night of another program (another circle than the monitor's) and a corrupt file.
    other = program_from_mapping(
        {"radius_mm": 50.0, "feed_mm_per_min": 6000.0, "cycles_per_direction": 3, "dwell_s": 0.5}
    )
    wrong = rig / "wrong.mcap"
    when = int((START + timedelta(days=5.5)).timestamp() * 1e9)
    write_mcap(simulate_run(other, sensor=SENSOR, seed=5, t0_ns=when)[0], wrong)
    reference = rig.parent / (rig.name + "-ref")
    shutil.copytree(rig, reference)
    for path in (junk, wrong):
        code, record = judge(config, path, capsys)
        assert record["state"] == "invalid" and code == EXIT_CODES["invalid"] == 12
        assert record["invalid_reason"] and "\n" not in record["invalid_reason"]
    assert "program differs" in record["invalid_reason"]
    # the next valid night's chart statistics are those without the bad runs
    _, with_bad = judge(config, still, capsys)
    _, without = judge(reference / "monitor.toml", still, capsys)
    assert with_bad["chart"] == without["chart"] and with_bad["state"] == without["state"]
    # an invalid run never enters a baseline
    code = main(["baseline", "set", "--config", str(config), str(junk), str(still), str(still)])
    assert code == 2
    assert "invalid" in capsys.readouterr().err


@pytest.mark.slow
def test_two_nightly_processes_on_one_history_both_land(rig):
    config = rig / "monitor.toml"
    paths = [night(rig, 5), night(rig, 6)]
    script = Path(sys.executable).with_name("imu-square")
    procs = [
        subprocess.Popen(
            [str(script), "nightly", "--config", str(config), "--recording", str(p), "--json"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for p in paths
    ]
    outs = [p.communicate(timeout=300) for p in procs]
    for proc, (out, err) in zip(procs, outs, strict=True):
        assert proc.returncode in (0, 10), err
        assert json.loads(out.splitlines()[-1])["state"] in ("ok", "warning")
    with open_history(rig / "history.db") as h:
        names = {Path(r.recording_path).name for r in h.runs("m1")}
        assert {p.name for p in paths} <= names
        judged = {e.run_id for e in h.evaluations("m1")}
        assert {r.id for r in h.runs("m1") if Path(r.recording_path) in paths} <= judged
