"""A new machine set up as the README says: plan, init, three nights, baseline, a night ok.

Each night runs through the emulated board on a pseudo-terminal (the monitor
file's port "emulated"), recorded through the real serial path, as the
nightly timer would. Nothing the project itself wrote (the plan file, the
monitor file) may cause a warning: the analysis settings follow the program.
"""

import json

import pytest

from imu_square.cli import main
from imu_square.monitor.history.store import open_history
from imu_square.simulate import data_path


def _night(monitor, capsys):
    code = main(["nightly", "--config", str(monitor), "--json"])
    return code, json.loads(capsys.readouterr().out.strip().splitlines()[-1])


def _settings_warnings(record):
    """Warnings the project's own settings would cause (the cutoff, the period)."""
    return [w for w in record["warnings"] if "cutoff" in w or "period differs" in w]


def _set_up_and_run(folder, capsys, init_extra):
    monitor = folder / "mill-1.toml"
    argv = ["init", "--machine-id", "mill-1", "-o", str(monitor), "--history", "history.db"]
    assert main([*argv, *init_extra]) == 0
    capsys.readouterr()
    for _ in range(3):
        code, record = _night(monitor, capsys)
        assert code == 14 and record["state"] == "no_baseline", record
        assert _settings_warnings(record) == []
    with open_history(folder / "history.db") as history:
        runs = [str(r.id) for r in history.runs("mill-1", valid_only=True)]
    assert len(runs) == 3
    assert main(["baseline", "set", "--config", str(monitor), *runs]) == 0
    assert "warning" not in capsys.readouterr().err
    code, record = _night(monitor, capsys)
    # An unchanged machine: ok, or warning on the 2 % of in-control nights the charts are
    # designed to warn on (the emulated board's noise is not seeded); its change is noise.
    assert (record["state"], code) in (("ok", 0), ("warning", 10)), record
    assert abs(record["change_urad"]) < 4 * record["u_change_urad"]
    assert _settings_warnings(record) == []
    return record


@pytest.mark.slow
def test_a_fast_circle_from_plan_to_a_night_judged_ok(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    argv = ["plan", "--sensor", str(data_path("sensor_paper.toml"))]
    argv += ["--max-feed-mm-min", "30000", "--max-accel-m-s2", "10", "--travel-mm", "500"]
    assert main([*argv, "--time-s", "40", "--json", "-o", "plan.toml"]) == 0
    plan = json.loads(capsys.readouterr().out)
    assert plan["feeds_mm_per_min"] == [30000.0] and plan["circle_frequency_hz"][0] > 1.0
    record = _set_up_and_run(tmp_path, capsys, ["--program", "plan.toml"])
    assert record["recording"].startswith(str(tmp_path))


@pytest.mark.slow
def test_the_papers_test_from_init_to_a_night_judged_ok(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _set_up_and_run(tmp_path, capsys, [])
