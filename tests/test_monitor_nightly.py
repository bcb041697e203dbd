"""The monitor end to end through the CLI: real recordings, a real SQLite history.

A low-noise sensor on a brisk program (tests/monitor_rig.py) makes one night's
sigma about 2.5 µm/m, so a 10 µm/m degradation is four sigma: the designed
charts must find it within a few nights, and a clean sequence must raise no
alarm. The baseline and its alarm design (the slow part) are made once and
copied into each test.
"""

import json
import math
import re
import shutil
import subprocess
import sys
from dataclasses import replace
from datetime import timedelta
from pathlib import Path

import pytest
from monitor_rig import ALPHA, SENSOR, START, copy_base, judge, make_base, night

from imu_square.cli import main
from imu_square.io.mcap import write_mcap
from imu_square.monitor.history.store import open_history
from imu_square.monitor.schedule import EXIT_CODES
from imu_square.program import program_from_mapping
from imu_square.simulate.run import simulate_run


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """A monitor folder with a history holding a 5-night baseline and its alarm design."""
    return make_base(tmp_path_factory.mktemp("monitor"))


@pytest.fixture
def rig(base, tmp_path):
    """A copy of the baseline's monitor folder for one test."""
    return copy_base(base, tmp_path)


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
@pytest.mark.filterwarnings("always::imu_square.errors.ImuSquareWarning")
def test_the_nights_alert_is_kept_in_the_history_and_an_old_outbox_folder_is_not_used(rig, capsys):
    config = rig / "monitor.toml"
    # A monitor file of an older imu-square names the folder its alerts waited in.
    text = config.read_text().replace(
        "[alerts.json_file]", '[alerts]\noutbox = "spool"\n\n[alerts.json_file]'
    )
    config.write_text(text)
    for day in (5, 6):
        code = main(["nightly", "--config", str(config), "--recording", str(night(rig, day))])
        assert code in (EXIT_CODES["ok"], EXIT_CODES["warning"])
        err = capsys.readouterr().err
        assert err.count("warning: ") == 1
        assert f"{config}: [alerts] outbox is no longer used: the pending alerts are kept" in err
    assert not (rig / "spool").exists() and not (rig / "data" / "outbox").exists()
    # Each night's alert was stored with the night, then delivered to the JSON file.
    with open_history(rig / "history.db") as h:
        rows = h.outbox("m1", "delivered")
        runs = {Path(r.recording_path).name: r.id for r in h.runs("m1")}
    assert [r.alert["record"]["run_id"] for r in rows] == [
        runs["night-005.mcap"],
        runs["night-006.mcap"],
    ]
    assert {r.sink for r in rows} == {"json_file"}
    assert json.loads((rig / "data" / "alert.json").read_text())["alert_id"] == rows[-1].alert_id


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


@pytest.mark.slow
def test_a_night_through_the_emulated_board_ends_in_a_verdict(rig, capsys):
    """The nightly job as cron runs it: record through a pty, judge, chart, report, exit."""
    (rig / "machine.toml").write_text(
        '[machine]\nname = "m1"\n[geometry]\nmachine_squareness_um_per_m = 20.0\n'
        "[servo_mismatch]\ntau_x_ms = 2.0\ntau_y_ms = 2.5\n"
    )
    (rig / "sensor.toml").write_text(
        "[sensor]\nsample_rate_hz = 500.0\nnoise_density_ug_rthz = 0.5\neps_c_deg = 2.1\n"
        "beta_urad = 40.0\n"
    )
    text = (rig / "monitor.toml").read_text()
    (rig / "monitor.toml").write_text(
        text + '\n[sensor]\nport = "emulated"\n\n[emulated]\nmachine = "machine.toml"\n'
        'sensor = "sensor.toml"\nspeed = 20.0\n'
    )
    code = main(["nightly", "--config", str(rig / "monitor.toml"), "--json"])
    out, err = capsys.readouterr()
    record = json.loads(out.strip().splitlines()[-1])
    assert record["state"] in ("ok", "warning") and code == EXIT_CODES[record["state"]]
    assert abs(record["change_urad"]) < 4 * record["u_change_urad"]
    assert record["recording"].startswith(str(rig / "data" / "m1-"))
    assert "squareness unchanged" in err or "may be changing" in err
    for name in ("m1-trend.png", "m1-report.html"):
        assert (rig / "data" / name).stat().st_size > 10_000
    assert main(["nightly", "--config", str(rig / "monitor.toml"), "--check"]) == 0
    assert "ok" in capsys.readouterr().err


# ---- found by an adversarial review of the monitor, each kept as a regression test ----


@pytest.mark.slow
def test_a_night_inside_the_baselines_dates_is_judged_not_waved_through(rig, capsys):
    # the baseline's runs are nights 0-4; a night recorded between two of them is charted
    path = night(rig, 2, alpha=ALPHA + 50e-6, seed=77)
    _, record = judge(rig / "monitor.toml", path, capsys)
    assert record["state"] == "alarm" and record["change_urad"] > 40


@pytest.mark.slow
def test_a_machine_change_that_follows_the_season_is_not_taken_for_drift(rig, capsys):
    # a temperature channel but no sensor drift; the ambient rises 0.4 °C a night while the
    # machine creeps 3 µm/m a night: no within-night slope, so nothing is "corrected" away
    config = rig / "monitor.toml"
    states = []
    for k, day in enumerate(range(5, 13)):
        sensor = replace(SENSOR, temperature_c=22.0 + 0.4 * k)
        _, record = judge(
            config, night(rig, day, alpha=ALPHA + 3e-6 * (k + 1), sensor=sensor), capsys
        )
        states.append(record["state"])
        assert not record["drift_corrected"]
    assert "alarm" in states


@pytest.mark.slow
def test_a_replaced_sensor_makes_the_baseline_stale(rig, capsys):
    other = replace(SENSOR, model="spare", beta_rad=SENSOR.beta_rad + 200e-6)
    code, record = judge(rig / "monitor.toml", night(rig, 5, sensor=other), capsys)
    assert record["state"] == "stale_baseline" and code == 13
    assert "the sensor was replaced" in record["verdict"]
    # and a small remount (0.1 deg) is seen: the tolerance is the nights' eps_c scatter
    turned = replace(SENSOR, eps_c_rad=SENSOR.eps_c_rad + math.radians(0.1))
    rig2 = rig / "second"
    rig2.mkdir()
    code, record = judge(rig / "monitor.toml", night(rig2, 6, sensor=turned), capsys)
    assert record["state"] == "stale_baseline"


@pytest.mark.slow
def test_bad_inputs_found_by_review_are_one_line_and_store_nothing(rig, capsys):
    config = rig / "monitor.toml"
    with open_history(rig / "history.db") as h:
        before = len(h.runs("m1"))
    # a baseline that is refused stores none of its new recordings
    junk = rig / "junk.mcap"
    junk.write_bytes(b"junk")
    good = [str(night(rig, d)) for d in (20, 21)]
    assert main(["baseline", "set", "--config", str(config), str(junk), *good]) == 2
    assert "invalid" in capsys.readouterr().err
    with open_history(rig / "history.db") as h:
        assert len(h.runs("m1")) == before
    # NaN samples are named as such
    rec_path = night(rig, 22)
    from imu_square.io.mcap import read_mcap

    rec = read_mcap(rec_path)
    rec.accel[100:105, 0] = float("nan")
    write_mcap(rec, rig / "nan.mcap")
    _, record = judge(config, rig / "nan.mcap", capsys)
    assert record["state"] == "invalid" and "not numbers (NaN or infinite)" in record["reason"]
    # a recording older than the baseline is kept, not judged against it, and no crash
    code, record = judge(config, night(rig, -3), capsys)
    assert code == EXIT_CODES["no_baseline"] and record["state"] == "no_baseline"
    # a data folder that cannot be made: one line before anything is stored
    (rig / "blocker").write_text("a file")
    text = (rig / "monitor.toml").read_text().replace('data_dir = "data"', 'data_dir = "blocker/x"')
    (rig / "bad.toml").write_text(text)
    with open_history(rig / "history.db") as h:
        before = len(h.runs("m1"))
    assert main(["nightly", "--config", str(rig / "bad.toml"), "--recording", good[0]]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot create the data folder" in err[0]
    with open_history(rig / "history.db") as h:
        assert len(h.runs("m1")) == before
    # a relative --recording is stored with its absolute path
    import os

    cwd = os.getcwd()
    os.chdir(rig)
    try:
        _, record = judge("monitor.toml", Path(good[1]).name, capsys)
    finally:
        os.chdir(cwd)
    assert record["recording"] == str(Path(good[1]).resolve())


TWO_FEEDS = {
    "radius_mm": 25.0,
    "feeds_mm_per_min": [9000.0, 4500.0],
    "cycles_per_direction": [3, 2],
    "dwell_s": 0.5,
}


def test_a_two_feed_program_is_refused_before_the_machine_runs(rig, capsys):
    # the monitor tracks one feed's theta_y - theta_x: a two-feed program's night would be
    # recorded (the machine run, the warm-up spent) only to be refused at the analysis
    (rig / "two.toml").write_text(program_from_mapping(TWO_FEEDS).to_toml())
    program_line = re.compile(r'(?m)^file = ".*"$')
    text = program_line.sub(f'file = "{rig / "two.toml"}"', (rig / "monitor.toml").read_text())
    (rig / "two-feed.toml").write_text(text)
    with open_history(rig / "history.db") as h:
        before = len(h.runs("m1"))
    config = str(rig / "two-feed.toml")
    for argv in (
        ["nightly", "--config", config],
        ["nightly", "--config", config, "--check"],
        ["baseline", "set", "--config", config, "--last", "3"],
        ["replay", "--config", config, str(night(rig, 30))],
    ):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1, err
        assert "two.toml runs 2 feeds (9000, 4500 mm/min)" in err[0]
        assert "analyze --separate-gravity" in err[0] and "period_s" not in err[0]
    assert not list(rig.glob("data/*.mcap"))  # the machine never ran
    with open_history(rig / "history.db") as h:
        assert len(h.runs("m1")) == before


def test_a_two_feed_recording_is_an_invalid_night_named_as_such(rig, capsys):
    text = re.sub(r'(?m)^file = ".*"$', 'file = ""', (rig / "monitor.toml").read_text())
    (rig / "paper.toml").write_text(text)
    when = int((START + timedelta(days=6)).timestamp() * 1e9)
    rec, _ = simulate_run(program_from_mapping(TWO_FEEDS), sensor=SENSOR, seed=8, t0_ns=when)
    path = rig / "two-feed.mcap"
    write_mcap(rec, path)
    code, record = judge(rig / "paper.toml", path, capsys)
    assert code == EXIT_CODES["invalid"] and record["state"] == "invalid"
    assert record["invalid_reason"].startswith("the recording runs 2 feeds (9000, 4500 mm/min)")


@pytest.mark.slow
def test_the_trend_chart_keeps_an_earlier_baselines_alarm_and_its_climb(rig, capsys):
    # A +12 µm/m step fires the alarm; after the repair a new baseline is set. The
    # chart still draws the first period against its own baseline: its charts' climb
    # to the alarm, its limits, and where each baseline's runs began.
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    from imu_square.monitor.config import read_monitor
    from imu_square.monitor.night import judge_history
    from imu_square.monitor.report.figures import plot_trend

    config = rig / "monitor.toml"
    states = [
        judge(config, night(rig, d, alpha=ALPHA + 12e-6), capsys)[1]["state"] for d in range(5, 12)
    ]
    assert "alarm" in states
    runs = [str(night(rig, d)) for d in (12, 13, 14)]
    assert main(["baseline", "set", "--config", str(config), *runs]) == 0
    judge(config, night(rig, 15), capsys)
    with open_history(rig / "history.db") as history:
        assessment = judge_history(read_monitor(config), history)
    (first,) = assessment.earlier
    charted = [n for n in first.nights if n.chart is not None]
    assert [n.state for n in charted][-1] == "alarm" and len(charted) == 7
    climb = [n.chart.cusum_pos for n in charted]
    assert (
        climb[-1] > first.design.cusum.limit
        or max(n.chart.z for n in charted) > first.design.shewhart.limit
    )
    drawn = {}

    def savefig(fig, *args, **kwargs):
        bottom = fig.axes[1]
        drawn["ewma"] = [line for line in bottom.lines if line.get_color() == "tab:cyan"]
        drawn["starts"] = [line for line in fig.axes[0].lines if line.get_linestyle() == ":"]

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(plt.Figure, "savefig", savefig)
        plot_trend(assessment, rig / "trend.png")
    assert len(drawn["ewma"]) == 2  # one EWMA line for each baseline's period
    assert len(drawn["starts"]) == 2  # a start mark for each baseline


def test_a_baseline_of_another_test_is_refused_naming_both_programs(tmp_path, capsys):
    # The monitor file names no program: the paper's test. Recordings of the rig's
    # r = 25 mm circle used to be accepted, and every later night was then invalid.
    text = (
        '[monitor]\nmachine_id = "m1"\nhistory = "history.db"\ndata_dir = "data"\n\n'
        '[program]\nfile = ""\n\n[analysis]\nbootstrap = 0\n'
    )
    (tmp_path / "monitor.toml").write_text(text)
    runs = [str(night(tmp_path, d)) for d in range(3)]
    code = main(["baseline", "set", "--config", str(tmp_path / "monitor.toml"), *runs])
    err = [line for line in capsys.readouterr().err.splitlines() if "schema" not in line]
    assert code == 2 and len(err) == 1
    assert (
        "the recording's program differs from the monitor's: r = 25 mm at 9000 mm/min, 5 "
        "cycles each way ran, the monitor's is r = 100 mm at 6000 mm/min, 15 cycles each way"
        in err[0]
    )
    with open_history(tmp_path / "history.db") as history:
        assert history.runs("m1") == [] and history.current_baseline("m1") is None


@pytest.mark.slow
def test_an_invalid_night_after_an_alarm_reports_the_alarm_too(rig, capsys):
    # An alarm stands until a new baseline is set: a cut recording after it is an
    # invalid night, and the verdict, the alert, the metrics, the report and the exit
    # code all still say the machine is in alarm.
    config = rig / "monitor.toml"
    text = config.read_text() + '\n[metrics]\ntextfile = "data/m1.prom"\n'
    config.write_text(text)
    for day in range(5, 12):
        code, record = judge(config, night(rig, day, alpha=ALPHA + 15e-6), capsys)
        if record["state"] == "alarm":
            break
    assert record["state"] == "alarm", "a 6-sigma step must alarm within a week"
    fired = record["recorded_at"][:10]
    cut = rig / "cut.mcap"
    cut.write_bytes(night(rig, 12).read_bytes()[:20_000])
    code, record = judge(config, cut, capsys)
    assert record["state"] == "invalid" and record["machine_state"] == "alarm"
    assert code == EXIT_CODES["alarm"]
    assert record["alarm_since"][:10] == fired
    assert f"the machine stands in alarm since {fired}" in record["verdict"]
    alert = json.loads((rig / "data" / "alert.json").read_text())
    assert alert["state"] == "alarm" and "stands in alarm" in alert["verdict"]
    metrics = (rig / "data" / "m1.prom").read_text()
    assert 'imu_square_state{machine_id="m1",state="alarm"} 1' in metrics
    report = (rig / "data" / "m1-report.html").read_text()
    assert '<p class="verdict alarm">' in report and "stands in alarm" in report


def test_a_recording_of_another_machine_or_of_no_date_is_refused_and_not_stored(rig, capsys):
    # A recording imported with --machine-id mill-4 used to enter m1's history; one whose
    # clock counted from power-on was dated 1970 and judged "before the baseline".
    from imu_square.io.mcap import read_mcap

    config = rig / "monitor.toml"
    good = read_mcap(night(rig, 5))
    other, undated = rig / "other.mcap", rig / "undated.mcap"
    imported = {**good.metadata, "producer": "imu-square import"}  # as import writes it
    write_mcap(replace(good, machine_id="mill-4", metadata=imported), other)
    write_mcap(replace(good, time_ns=good.time_ns - good.time_ns[0] + 1_234_500_000_000), undated)
    with open_history(rig / "history.db") as h:
        before = len(h.runs("m1"))
    for path, why in ((other, "recorded on machine 'mill-4', not this monitor's 'm1'"),
                      (undated, "its time (1234.500 s since 1970) is no date")):  # fmt: skip
        assert main(["nightly", "--config", str(config), "--recording", str(path)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and why in err[0], err
        assert main(["replay", "--config", str(config), "--jobs", "1", str(path)]) == 0
        assert "1 failed" in capsys.readouterr().out
    with open_history(rig / "history.db") as h:
        assert len(h.runs("m1")) == before


@pytest.mark.slow
def test_a_busy_history_keeps_the_night_says_so_and_stores_it_first_next_time(rig, capsys):
    # Another process holds the history's write lock longer than the monitor waits:
    # nightly says it is waiting, keeps the recording for later, names the command
    # that stores it now, and the alert (sent without the history) says so.
    config = rig / "monitor.toml"
    text = config.read_text().replace(
        'data_dir = "data"', 'data_dir = "data"\nbusy_timeout_s = 3.0'
    )
    config.write_text(text)
    release = rig / "release"
    child = Path(__file__).with_name("history_child.py")
    holder = subprocess.Popen(
        [sys.executable, str(child), "hold", str(rig / "history.db"), "1", str(release)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline() == "holding\n", holder.stderr.read()
        tonight = night(rig, 5)
        code = main(["nightly", "--config", str(config), "--recording", str(tonight)])
        err = capsys.readouterr().err
    finally:
        release.touch()
        holder.communicate(timeout=60)
    assert code == 2
    assert "is busy (another process is writing it): waiting up to 1 s more" in err
    assert f"its recording {tonight} is kept; the next night stores it first, or now: " in err
    assert f"imu-square nightly --config {config} --recording {tonight}" in err
    alert = json.loads((rig / "data" / "alert.json").read_text())
    assert alert["state"] == "invalid" and "could not be stored yet" in alert["verdict"]
    # the next night stores the kept one first, then itself
    code, record = judge(config, night(rig, 6), capsys)
    assert record["state"] in ("ok", "warning")
    with open_history(rig / "history.db") as h:
        stored = [Path(r.recording_path).name for r in h.runs("m1")]
    assert stored[-2:] == ["night-005.mcap", "night-006.mcap"]
    assert not (rig / "data" / "nights-to-store.txt").exists()


def test_the_anchored_machine_squareness_comes_with_its_uncertainty_everywhere(rig, capsys):
    # It used to appear only in the verdict's text, without its uncertainty.
    config = rig / "monitor.toml"
    argv = ["baseline", "anchor", "--config", str(config), "--ballbar", "21.5", "--u", "2.0"]
    assert main(argv) == 0
    _, record = judge(config, night(rig, 5), capsys)
    u = math.hypot(2.0, record["u_change_urad"])
    assert record["machine_squareness_urad"] == pytest.approx(21.5 + record["change_urad"])
    assert record["u_machine_squareness_urad"] == pytest.approx(u)
    value = record["machine_squareness_urad"]
    assert f"machine squareness {value:+.1f} ± {u:.1f} µm/m (k=1)" in record["verdict"]
    assert main(["history", "--config", str(config)]) == 0
    table = capsys.readouterr().out.split("\ndiagnostics\n")[0].splitlines()  # the runs
    assert "machine µm/m" in table[0] and f"{value:+7.1f} ± {u:5.1f}" in table[-1]


def test_an_unexpected_numerical_failure_is_one_line_naming_its_step(rig, capsys, monkeypatch):
    # scipy's nct overflowed in baseline set as a bare library traceback; any such failure
    # in a step is one line that names it, and a failed design stores no baseline.
    from imu_square.monitor.stats import alarms
    from imu_square.pipeline import squareness

    config = rig / "monitor.toml"
    with open_history(rig / "history.db") as h:
        before = h.current_baseline("m1").id

    def overflow(*args, **kwargs):
        raise OverflowError("Result of tgamma is too large to represent")

    monkeypatch.setattr(alarms, "design_alarms", overflow)
    runs = [str(night(rig, d)) for d in (5, 6, 7)]
    assert main(["baseline", "set", "--config", str(config), *runs]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.endswith(
        "error: designing the alarm charts failed: OverflowError: Result of tgamma is too "
        "large to represent"
    )
    with open_history(rig / "history.db") as h:
        assert h.current_baseline("m1").id == before

    def broken(*args, **kwargs):
        raise ValueError("array must not contain infs or NaNs")

    monkeypatch.setattr(squareness, "analyze", broken)
    code, record = judge(config, night(rig, 8), capsys)
    assert record["state"] == "invalid" and code == EXIT_CODES["invalid"]
    assert record["invalid_reason"] == (
        "the analysis failed: ValueError: array must not contain infs or NaNs"
    )


def test_a_cut_recording_is_judged_when_its_analysis_accepts_it_invalid_when_not(rig, capsys):
    # The README's table said 3 for an incomplete recording while the monitor exited 12.
    config = rig / "monitor.toml"
    whole = night(rig, 5).read_bytes()
    lead_out_lost = rig / "cut-late.mcap"
    lead_out_lost.write_bytes(whole[: len(whole) - 2_000])  # the last chunk, in the lead-out
    code, record = judge(config, lead_out_lost, capsys)
    assert record["state"] in ("ok", "warning") and code == EXIT_CODES[record["state"]]
    assert any("incomplete MCAP file" in w for w in record["warnings"])
    block_lost = rig / "cut-early.mcap"
    block_lost.write_bytes(whole[: len(whole) // 2])  # the second block is gone
    code, record = judge(config, block_lost, capsys)
    assert record["state"] == "invalid" and code == EXIT_CODES["invalid"] == 12
