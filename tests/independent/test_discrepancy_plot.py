"""Where ``imu-square discrepancy`` says a gap left in the transient windows lies.

A mode the generator rings at 80 Hz through its raised-cosine feed ramps, on a
short circle at the paper's 500 Hz, analysed through the real CLI with the
vibration candidate left out (``--effects-allowed backlash``), so the ringing
has no candidate and stays a gap in the transient view. The JSON must say when
and at which frequency, and the ``--plot`` figure must be written.
"""

import json
import math

from generator import generate

from imu_square.cli import main
from imu_square.discrepancy.layout import TRANSIENT_BIN_S, TRANSIENT_WINDOW_S
from imu_square.io.mcap import write_mcap
from imu_square.program.spec import TestProgram

SHORT = TestProgram(radius_m=0.05, feed_m_per_s=0.05, cycles_per_direction=4, dwell_s=1.0)
SENSOR_500 = {"rate_hz": 500.0, "eps_c_rad": math.radians(2.1)}
MODE_HZ, ZETA = 80.0, 0.05


def test_a_ringing_at_block_starts_is_located_in_time_and_frequency(tmp_path, capsys):
    # participation 10 rings about 4 mm/s^2 at the windows' start, 2.5 times the noise of a
    # 2 ms bin (one sample at 500 Hz)
    mode = {"freq_hz": MODE_HZ, "zeta": ZETA, "participation": 10.0}
    rec, _ = generate(SHORT, {"mode_x": mode, "mode_y": dict(mode)}, SENSOR_500, seed=2)
    path, plot = tmp_path / "ring.mcap", tmp_path / "gaps.png"
    write_mcap(rec, path)
    argv = ["discrepancy", str(path), "--json", "--plot", str(plot), "--no-suggest"]
    code = main([*argv, "--effects-allowed", "backlash"])
    doc = json.loads(capsys.readouterr().out)
    assert code == 0 and doc["named_effects"] == []
    left = {g["view"]: g for g in doc["gap_left"]}
    assert "transients" in left, doc["headline"]
    gap = left["transients"]
    # a ringing decays by exp(-2 pi zeta) = 0.73 a period: its largest bin is within its
    # first two periods from the window's start (noise of a bin is 0.4 of the peak)
    assert gap["transient"]["time_into_window_ms"] <= (2 / MODE_HZ + TRANSIENT_BIN_S) * 1e3
    # the periodogram of 0.25 s windows resolves 1 / 0.25 s = 4 Hz; noise-free, the 2 ms bin
    # means of the damped ringing (f sqrt(1 - zeta^2) = 79.9 Hz) peak within 0.5 Hz of it,
    # whatever its phase and the windows' start
    resolution = 1.0 / TRANSIENT_WINDOW_S
    band = gap["band"]
    assert abs(band["strongest_hz"] - MODE_HZ) <= resolution
    assert band["band_hz"][0] <= MODE_HZ <= band["band_hz"][1]
    assert band["nyquist_hz"] == 0.5 / TRANSIENT_BIN_S
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
