"""A small monitor set-up the monitor's tests share: a brisk low-noise program and nights.

A low-noise sensor (0.5 µg/√Hz at 500 Hz) on a short brisk program (r = 25 mm
at 9000 mm/min, 5 cycles each way) makes one night's sigma about 2.5 µm/m.
"""

import contextlib
import io
import json
import math
import shutil
from datetime import UTC, datetime, timedelta

from imu_square.cli import main
from imu_square.io.mcap import write_mcap
from imu_square.monitor.history.store import open_history
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
# The nightly diagnostics (on by default) have their own tests (test_monitor_diagnostics.py):
# the monitor's other tests do without their fit's second a night.
NO_DIAGNOSTICS = """
[diagnostics]
effects = []
"""
MONITOR = (
    """\
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
    + NO_DIAGNOSTICS
)


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


def judge(config, path, capsys=None):
    """``imu-square nightly --config C --recording P --json``: exit code and record."""
    argv = ["nightly", "--config", str(config), "--recording", str(path), "--json"]
    if capsys is None:
        buffer = io.StringIO()
        with contextlib.redirect_stdout(buffer):
            code = main(argv)
        out = buffer.getvalue()
    else:
        code = main(argv)
        out = capsys.readouterr().out
    return code, json.loads(out.strip().splitlines()[-1])


def make_base(folder, nights=5, sensor=SENSOR):
    """A monitor folder whose history holds a baseline of ``nights`` nights and its design."""
    (folder / "program.toml").write_text(PROGRAM.to_toml())
    (folder / "monitor.toml").write_text(MONITOR.format(program=folder / "program.toml"))
    runs = [str(night(folder, d, sensor=sensor)) for d in range(nights)]
    assert main(["baseline", "set", "--config", str(folder / "monitor.toml"), *runs]) == 0
    return folder


def copy_base(base, folder):
    """A copy of a base monitor folder (the history through the backup API)."""
    for name in ("program.toml", "monitor.toml"):
        shutil.copy(base / name, folder / name)
    with open_history(base / "history.db") as h:
        h.backup(folder / "history.db")
    return folder
