"""The JSON keys written are exactly those of docs/model.md's "Quantity names" table."""

import json
import re
from pathlib import Path

import pytest

from imu_square.cli import main

MODEL_MD = Path(__file__).resolve().parents[1] / "docs" / "model.md"
RECORDING = Path(__file__).resolve().parents[1] / "recordings" / "square_20um.mcap"


def _table(heading_pattern):
    """Rows of the first table after the heading or paragraph matching the pattern."""
    text = MODEL_MD.read_text(encoding="utf-8")
    start = re.search(heading_pattern, text).end()
    rows = []
    for line in text[start:].splitlines():
        if line.startswith("|"):
            rows.append([c.strip() for c in line.strip("|").split("|")])
        elif rows:
            break
    return rows[2:]  # past the header and the ---|--- line


def _documented():
    keys = {}
    for row in _table(r"## Quantity names"):
        for group in (g.strip() for g in row[1].split(",")):
            keys.setdefault(group, set()).update(re.findall(r"`([^`]+)`", row[0]))
    legacy = {}
    for row in _table(r"\*\*Kept for one release\*\*"):
        legacy.setdefault(row[1], set()).update(re.findall(r"`([^`]+)`", row[0]))
    return keys, legacy


def test_the_table_parses():
    keys, legacy = _documented()
    assert {"analyze", "direction", "per_cycle", "truth"} <= set(keys)
    assert "machine_squareness_rad" in keys["truth"]
    assert legacy["truth"] == {
        "alpha_rad",
        "beta_rad",
        "local_squareness_rad",
        "expected_theta_diff_exact_rad",
        "expected_theta_diff_rad",
    }


@pytest.mark.slow
def test_analyze_json_and_truth_keys_match_the_table(tmp_path, capsys):
    keys, legacy = _documented()
    assert main(["analyze", str(RECORDING), "--json", "--bootstrap", "0"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(doc) == keys["analyze"] | legacy["analyze"]
    assert set(doc["ccw"]) == set(doc["cw"]) == keys["direction"]
    assert set(doc["per_cycle"]) == keys["per_cycle"]

    out = tmp_path / "run.mcap"
    assert main(["simulate", "-o", str(out), "--effects", "servo_mismatch"]) == 0
    truth = json.loads((tmp_path / "run.truth.json").read_text())
    assert set(truth) == keys["truth"] | legacy["truth"]
    # a legacy key keeps its value beside the key that replaces it
    assert truth["alpha_rad"] == truth["machine_squareness_rad"]
    assert truth["expected_theta_diff_exact_rad"] == truth["expected_squareness_rad"]


@pytest.mark.slow
def test_separate_gravity_json_keys_match_the_table(tmp_path, capsys):
    from imu_square.io.mcap import write_mcap
    from imu_square.program import TestProgram
    from imu_square.simulate import MachineModel, SensorModel, simulate_run

    keys, _legacy = _documented()
    program = TestProgram(
        radius_m=0.05, feeds_m_per_s=(0.1, 0.05), cycles_per_feed=(4, 3), dwell_s=1.0
    )
    sensor = SensorModel(sample_rate_hz=200.0, noise_density_m_s2_rthz=1e-6)
    rec, truth = simulate_run(program, MachineModel(tilt_per_m=(0, 1e-4, 0, 0)), sensor, seed=1)
    path = tmp_path / "two.mcap"
    write_mcap(rec, path)
    assert main(["analyze", str(path), "--separate-gravity", "--json", "--bootstrap", "0"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(doc) == keys["separate"]
    # each feed: its own keys and a plain result's (recording is both)
    plain = keys["analyze"] - {"convergence"}
    for feed in doc["feeds"]:
        assert set(feed) == keys["feed"] | plain
    assert set(truth["feeds"][0]) == {
        "feed_mm_per_min",
        "omega_rad_s",
        "amplitude_m_s2",
        "servo_mismatch_rad",
        "servo_amplitude_phase_rad",
        "gravity_phase_rad",
        "expected_squareness_rad",
    }


def test_sample_recordings_truth_files_carry_todays_keys():
    # regenerate with recordings/make_recordings.py when the truth gains a key
    keys, legacy = _documented()
    for path in sorted(RECORDING.parent.glob("*.truth.json")):
        truth = json.loads(path.read_text(encoding="utf-8"))
        assert set(truth) == keys["truth"] | legacy["truth"], path.name
