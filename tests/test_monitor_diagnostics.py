"""The monitor's nightly diagnostics end to end through the CLI: real recordings, a real
SQLite history.

The machine of tests/monitor_rig.py with a backlash of X: its baseline is set from five
nights, then the backlash grows by 3 µm a week. The backlash's own alarm (asked for in
the monitor file, off by default) must fire while the squareness stays ``ok``; every
valid night stores every diagnostic, named or not; ``history``, its charts and the
report show them; a fit that fails loses nothing of the night; ``replay`` rebuilds the
diagnostics of an archive whose runs were stored without them.
"""

import json
from datetime import timedelta

import pytest
from doc_quotes import quoted_form
from monitor_rig import (
    ALPHA,
    MONITOR,
    NO_DIAGNOSTICS,
    PROGRAM,
    SENSOR,
    START,
    copy_base,
    judge,
)

from imu_square.cli import main
from imu_square.io.mcap import write_mcap
from imu_square.monitor.diagnostics.catalog import DEFAULT_EFFECTS, diagnostics_of
from imu_square.monitor.diagnostics.settings import DiagnosticSettings
from imu_square.monitor.history.store import open_history
from imu_square.monitor.schedule import EXIT_CODES
from imu_square.simulate.geometry import Geometry
from imu_square.simulate.machine import MachineModel
from imu_square.simulate.run import simulate_run

BACKLASH_UM = 2.0
GROWTH_UM_PER_DAY = 3.0 / 7
ALARMED = "\n[diagnostics.alarms]\nbacklash_x_um = 3.0\n"


def backlash_night(folder, day, backlash_um=BACKLASH_UM):
    """One night of the rig's machine with a backlash of X; its path."""
    machine = MachineModel(
        geometry=Geometry(machine_squareness_rad=ALPHA),
        tau_x_s=2e-3,
        tau_y_s=2.5e-3,
        backlash_x_m=backlash_um * 1e-6,
    )
    when = START + timedelta(days=day)
    rec, _ = simulate_run(
        PROGRAM,
        machine,
        SENSOR,
        seed=2000 + day,
        t0_ns=int(when.timestamp() * 1e9),
        lead_in_s=1.0,
        lead_out_s=1.0,
    )
    path = folder / f"night-{day:03d}.mcap"
    write_mcap(rec, path)
    return path


def _folder(folder, extra="", alert_states=None):
    text = MONITOR.format(program=folder / "program.toml").replace(NO_DIAGNOSTICS, "\n")
    if alert_states is not None:
        text = text.replace(
            'states = ["ok", "warning", "alarm", "invalid", "stale_baseline", "no_baseline"]',
            f'states = {alert_states!r}\nmode = "append"'.replace("'", '"'),
        )
    (folder / "program.toml").write_text(PROGRAM.to_toml())
    (folder / "monitor.toml").write_text(text + extra)
    return folder / "monitor.toml"


@pytest.fixture(scope="module")
def grown(tmp_path_factory):
    """A 5-night baseline, then nights whose backlash grows 3 µm a week, judged nightly."""
    folder = tmp_path_factory.mktemp("diagnostics")
    config = _folder(folder, ALARMED, alert_states=["alarm"])  # the sink takes alarms only
    runs = [str(backlash_night(folder, d)) for d in range(5)]
    assert main(["baseline", "set", "--config", str(config), *runs]) == 0
    records, codes = [], []
    for day in range(5, 12):
        grown_um = BACKLASH_UM + GROWTH_UM_PER_DAY * (day - 5)
        code, record = judge(config, backlash_night(folder, day, grown_um))
        records.append((day, grown_um, record))
        codes.append(code)
        if record["diagnostic_alarms"]:
            break
    return folder, records, codes


@pytest.mark.slow
def test_backlash_growing_3um_a_week_fires_its_alarm_while_the_squareness_stays_ok(grown):
    folder, records, codes = grown
    # the first night after the baseline has the baseline's backlash: no alarm
    day, _, first = records[0]
    assert first["diagnostics"]["backlash_x"]["state"] == "ok"
    fired = [(day, um, r) for day, um, r in records if r["diagnostic_alarms"]]
    assert fired, "a backlash growing 3 µm a week must fire its alarm within the week"
    day, grown_um, record = fired[0]
    assert 5 < day <= 5 + 7 and record["diagnostic_alarms"] == ["backlash_x"]
    backlash = record["diagnostics"]["backlash_x"]
    assert backlash["state"] == "alarm" and backlash["unit"] == "µm"
    # the change seen is the growth put in
    assert backlash["change"] == pytest.approx(grown_um - BACKLASH_UM, abs=0.1)
    assert backlash["value"] == pytest.approx(grown_um, abs=0.1)
    assert "diagnostic alarm: backlash_x" in record["verdict"]
    # the clause as the user guide quotes it
    clause = quoted_form("docs/user-guide/diagnostics.md", "...; diagnostic alarm:")
    assert clause.search(record["verdict"]), (clause.pattern, record["verdict"])
    # the alarm went where the squareness's alarms go (the sink takes alarms only): the
    # night's alert alone, its state the squareness's
    (alert,) = map(json.loads, (folder / "data" / "alert.json").read_text().splitlines())
    assert alert["state"] == "ok" and "diagnostic alarm: backlash_x" in alert["verdict"]
    # the squareness stays ok every night, and the exit code is the squareness's as before
    assert [r["state"] for _, _, r in records] == ["ok"] * len(records)
    assert codes == [EXIT_CODES["ok"]] * len(records)


@pytest.mark.slow
def test_every_valid_night_stores_every_diagnostic_named_or_not(grown):
    folder, records, _ = grown
    settings = DiagnosticSettings()
    with open_history(folder / "history.db") as h:
        runs = h.runs("m1")
        fits = h.diagnostic_fits("m1", settings.key())
    assert {r.id for r in runs} == set(fits) and len(runs) == 5 + len(records)
    names = [d.name for d in diagnostics_of(DEFAULT_EFFECTS)]
    for fit in fits.values():
        assert fit.failure is None and fit.seconds > 0
        assert [v.name for v in fit.values] == names
        for v in fit.values:
            # a diagnostic one circle test cannot see is stored with its reason
            assert (v.value is None) == (v.missing_reason is not None)
            if v.value is not None:
                assert v.u_value > 0
    # vibration and spikes the machine does not have: stored near zero, with their u
    vib = [f.value("vibration_x") for f in fits.values()]
    assert all(abs(v.value) < 5 * v.u_value for v in vib)


@pytest.mark.slow
def test_history_its_charts_and_the_report_show_each_diagnostic(grown, capsys):
    folder, records, _ = grown
    config = str(folder / "monitor.toml")
    capsys.readouterr()
    assert main(["history", "--config", config]) == 0
    out = capsys.readouterr().out
    table = out.split("\ndiagnostics\n")[1].splitlines()
    assert "backlash_x µm" in table[0] and "servo_mismatch ms" in table[0]
    assert len(table) == 1 + 5 + len(records) + 1  # header, nights, the alarm standing
    assert table[-1].startswith("diagnostic alarms standing: backlash_x since")
    assert table[-2].split()[3].endswith("!")  # the last night past backlash_x's limit
    assert main(["history", "--config", config, "--plot", str(folder / "trend.png")]) == 0
    assert (folder / "trend-diagnostics.png").stat().st_size > 10_000
    capsys.readouterr()
    report = (folder / "data" / "m1-report.html").read_text()
    assert '<section id="diagnostics">' in report and "backlash_x" in report
    assert 'src="data:image/png;base64,' in report.split('<section id="diagnostics">')[1]
    assert (folder / "data" / "m1-diagnostics.png").is_file()
    assert main(["history", "--config", config, "--json"]) == 0
    record = json.loads(capsys.readouterr().out.splitlines()[-1])
    assert set(record["diagnostics"]) == {d.name for d in diagnostics_of(DEFAULT_EFFECTS)}


@pytest.mark.slow
def test_a_diagnostic_alarm_stands_when_the_diagnostic_settings_change(grown, tmp_path, capsys):
    # backlash_x's alarm fired on fits with our own trajectory's motion and the default
    # effects; with LinuxCNC's motion (nightly --motion linuxcnc), or fewer effects, no
    # diagnostic has a baseline, but the machine's backlash has not shrunk: the alarm
    # stands until a new baseline is set, and says on what fits
    from imu_square.monitor.config import read_monitor
    from imu_square.monitor.night import judge_history
    from imu_square.monitor.report.html import render_report
    from imu_square.monitor.verdict import iso

    folder, records, _ = grown
    config = read_monitor(folder / "monitor.toml")
    with open_history(folder / "history.db") as h:
        trajectory = judge_history(config, h)
        linuxcnc = judge_history(config.with_motion("linuxcnc"), h)
    fired = {t.diagnostic.name: t.alarm_since_ns for t in trajectory.diagnostics}
    assert fired["backlash_x"] is not None
    since = iso(fired["backlash_x"])[:10]
    standing = {t.diagnostic.name: t for t in linuxcnc.diagnostics}
    x = standing["backlash_x"]
    assert x.baseline is None and x.alarm_since_ns == fired["backlash_x"]
    assert x.fired_on == "the motion 'trajectory'"
    assert x.note.endswith(
        f"; its alarm on the fits with the motion 'trajectory' stands since {since}, until a "
        "new baseline is set"
    )
    # the other diagnostics had no alarm: no baseline, and nothing stands
    assert all(t.alarm_since_ns is None for n, t in standing.items() if n != "backlash_x")
    assert "stands since" not in standing["backlash_y"].note
    assert _alarm_cell(render_report(linuxcnc), "backlash_x") == f"alarm; {x.note}"
    # history under LinuxCNC's motion lists it with the alarms standing
    out = _history_with_linuxcnc_motion(folder, capsys)
    assert f"diagnostic alarms standing: backlash_x since {since}" in out
    # a night judged with fewer effects (a new key, fitted tonight): in alarm in its record,
    # which the alerts read, and its verdict says on what fits
    copy = copy_base(folder, tmp_path)
    text = (copy / "monitor.toml").read_text()
    (copy / "monitor.toml").write_text(text.replace(ALARMED, BACKLASH_ONLY))
    day, grown_um, _ = records[-1]
    code, record = judge(copy / "monitor.toml", backlash_night(copy, day + 1, grown_um))
    assert code == EXIT_CODES["ok"] and record["diagnostic_alarms"] == ["backlash_x"]
    assert record["diagnostics"]["backlash_x"]["change"] is None
    assert record["verdict"].endswith(
        f"; diagnostic alarm: backlash_x (alarm on the fits with other effects since {since}, "
        "until a new baseline is set): check the machine"
    )
    (alert,) = map(json.loads, (copy / "data" / "alert.json").read_text().splitlines()[-1:])
    assert "diagnostic alarm: backlash_x" in alert["verdict"]


@pytest.mark.slow
def test_the_diagnostics_chart_keeps_an_earlier_baselines_limits_and_alarm(grown, tmp_path, capsys):
    # After the backlash's alarm a new baseline is set from nights at 6 µm. The chart
    # draws each baseline's period against its own: both periods' limits at their own
    # baseline's numbers, and the alarm that fired in the first period.
    import shutil

    import matplotlib

    matplotlib.use("Agg")
    import numpy as np
    from matplotlib import pyplot as plt

    from imu_square.monitor.config import read_monitor
    from imu_square.monitor.history.encoding import datetime_from_ns
    from imu_square.monitor.night import judge_history
    from imu_square.monitor.report.diagnostics_figure import plot_diagnostics
    from imu_square.monitor.stats.alarms import AlarmDesign

    old, records, _ = grown
    folder = tmp_path / "m1"
    shutil.copytree(old, folder)
    config = folder / "monitor.toml"
    fired = next(r for _, _, r in records if r["diagnostic_alarms"])
    repaired = [str(backlash_night(folder, d, 6.0)) for d in (20, 21, 22)]
    assert main(["baseline", "set", "--config", str(config), *repaired]) == 0
    assert judge(config, backlash_night(folder, 23, 6.0), capsys)[1]["diagnostic_alarms"] == []
    with open_history(folder / "history.db") as h:
        assessment = judge_history(read_monitor(config), h)
        rows = h.baselines("m1")
        fits = h.diagnostic_fits("m1", DiagnosticSettings().key())
    assert len(rows) == 2 and len(assessment.earlier) == 1
    # each limit from its stored baseline: its nights' backlash_x, its stored design's L
    expected = []
    for row, truth_um in zip(rows, (BACKLASH_UM, 6.0), strict=True):
        v = np.array([fits[i].value("backlash_x").value for i in row.run_ids])
        u = np.array([fits[i].value("backlash_x").u_value for i in row.run_ids])
        assert np.mean(v) * 1e6 == pytest.approx(truth_um, abs=0.1)
        between = np.sqrt(max(0.0, np.var(v, ddof=1) - np.mean(u**2)))
        limit = AlarmDesign.from_json_dict(
            row.diagnostic_designs["backlash_x"]["design"]
        ).shewhart.limit
        expected.append((row, np.mean(v), between, limit))
    drawn = {}

    def savefig(fig, *args, **kwargs):
        (ax,) = [a for a in fig.axes if a.get_title(loc="left") == "backlash"]
        drawn["limits"] = [line for line in ax.lines if line.get_linestyle() == "--"]
        drawn["alarms"] = [line for line in ax.lines if line.get_marker() == "s"]
        drawn["starts"] = [line for line in ax.lines if line.get_linestyle() == ":"]

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(plt.Figure, "savefig", savefig)
        plot_diagnostics(assessment, folder / "diagnostics.png")
    assert len(drawn["starts"]) == 2  # where each baseline's runs begin
    second_start = datetime_from_ns(rows[1].first_run_at_ns)

    def _when(night):
        return datetime_from_ns(night.run.recorded_at_ns)

    by_period = {}
    for line in drawn["limits"]:  # upper and lower, each period
        by_period.setdefault(line.get_xdata()[0], []).append(line)
    assert sorted(map(len, by_period.values())) == [2, 2]
    uppers = [
        max(pair, key=lambda line: np.mean(line.get_ydata()))
        for _, pair in sorted(by_period.items())
    ]
    by_time = {
        _when(n): fits[n.run.id].value("backlash_x") for n in assessment.nights if n.run.id in fits
    }
    for line, (row, value, between, limit) in zip(uppers, expected, strict=True):
        dates = line.get_xdata()
        assert all((d < second_start) == (row is rows[0]) for d in dates)
        want = [(value + limit * np.hypot(by_time[d].u_value, between)) * 1e6 for d in dates]
        np.testing.assert_allclose(line.get_ydata(), want, rtol=1e-9)
    # the periods' limits differ by their baselines' backlash, about 4 µm
    gap = np.mean(uppers[1].get_ydata()) - np.mean(uppers[0].get_ydata())
    assert gap == pytest.approx((expected[1][1] - expected[0][1]) * 1e6, abs=0.3)
    # the alarm fired in the first period and stood to its end: its marker is there
    (alarm,) = drawn["alarms"]
    assert all(d < second_start for d in alarm.get_xdata())
    assert alarm.get_xdata()[0] == _when(assessment.night_of(fired["run_id"]))
    assert alarm.get_ydata()[0] == pytest.approx(fired["diagnostics"]["backlash_x"]["value"])


def test_a_failing_diagnostic_fit_keeps_the_night_and_notes_the_failure(
    tmp_path, monkeypatch, capsys, caplog
):
    from imu_square.discrepancy import diagnose

    config = _folder(tmp_path)

    def broken(*args, **kwargs):
        raise FloatingPointError("overflow encountered in multiply")

    monkeypatch.setattr(diagnose, "fit_effects", broken)
    code, record = judge(config, backlash_night(tmp_path, 0), capsys)
    # no baseline yet: the squareness's verdict as before, the diagnostics missing
    assert record["state"] == "no_baseline" and code == EXIT_CODES["no_baseline"]
    reason = "the diagnostic fit failed: FloatingPointError: overflow encountered in multiply"
    assert {d["missing_reason"] for d in record["diagnostics"].values()} == {reason}
    assert reason in caplog.text  # the CLI's stderr
    with open_history(tmp_path / "history.db") as h:
        (run,) = h.runs("m1")
        assert run.valid
        fit = h.diagnostic_fits("m1", DiagnosticSettings().key())[run.id]
    assert fit.failure == reason


@pytest.mark.parametrize("broken", ["nan value", "nan covariance", "infinite value"])
def test_a_fit_without_finite_numbers_keeps_the_night(tmp_path, monkeypatch, capsys, broken):
    import dataclasses
    import math

    from imu_square.discrepancy import diagnose
    from imu_square.monitor.diagnostics.fit import NOT_FINITE
    from imu_square.monitor.night import KEPT_NIGHTS

    config = _folder(tmp_path, '\n[diagnostics]\neffects = ["backlash"]\n')
    fit_effects = diagnose.fit_effects

    def non_finite(*args, **kwargs):
        fit = fit_effects(*args, **kwargs)
        if broken == "nan covariance":
            return dataclasses.replace(fit, covariance=fit.covariance * math.nan)
        bad = math.nan if broken == "nan value" else math.inf
        values = tuple(dataclasses.replace(v, value=bad) for v in fit.values)
        return dataclasses.replace(fit, values=values)

    monkeypatch.setattr(diagnose, "fit_effects", non_finite)
    code, record = judge(config, backlash_night(tmp_path, 0), capsys)
    # stored with its squareness verdict; the diagnostics missing, saying why
    assert record["state"] == "no_baseline" and code == EXIT_CODES["no_baseline"]
    assert {d["missing_reason"] for d in record["diagnostics"].values()} == {NOT_FINITE}
    with open_history(tmp_path / "history.db") as h:
        (run,) = h.runs("m1")
        assert run.valid
    assert not list(tmp_path.rglob(KEPT_NIGHTS))  # nothing left to store later


def test_bad_diagnostic_settings_are_one_line(tmp_path, capsys):
    config = _folder(tmp_path, '\n[diagnostics]\neffects = ["backlash", "cyclic_error"]\n')
    assert main(["history", "--config", str(config)]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "[diagnostics]" in err and "effects" in err and "'cyclic_error'" in err
    config = _folder(tmp_path, '\n[diagnostics]\neffects = ["backlash"]\n' + ALARMED)
    assert main(["history", "--config", str(config)]) == 0
    config = _folder(tmp_path, '\n[diagnostics]\neffects = ["servo_mismatch"]\n' + ALARMED)
    assert main(["history", "--config", str(config)]) != 0
    err = capsys.readouterr().err.strip()
    assert "[diagnostics.alarms]" in err and "backlash_x_um" in err
    # a step beyond what the effect's physical range can change is no design
    huge = '\n[diagnostics]\neffects = ["backlash"]\n[diagnostics.alarms]\nbacklash_x_um = 1e308\n'
    assert main(["history", "--config", str(_folder(tmp_path, huge))]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "backlash_x_um" in err and "200" in err


@pytest.mark.slow
def test_replay_rebuilds_an_archives_diagnostics_locally_and_on_dask(tmp_path, capsys):
    config = _folder(tmp_path, "\n[diagnostics]\neffects = []\n")
    archive = tmp_path / "archive"
    archive.mkdir()
    for day in range(4):
        backlash_night(archive, day, BACKLASH_UM + day)
    # the archive replayed without diagnostics: runs, no fits
    assert main(["replay", "--config", str(config), str(archive)]) == 0
    assert "4 analysed" in capsys.readouterr().out
    settings = DiagnosticSettings()
    with open_history(tmp_path / "history.db") as h:
        assert h.diagnostic_fits("m1", settings.key()) == {}
        run_ids = {r.recording_sha256: r.id for r in h.runs("m1")}
    # with the default diagnostics: every run read again for them, its row kept
    _folder(tmp_path)
    values = {}
    for engine, into in (([], "history.db"), (["--cluster", "local", "--jobs", "2"], "dask.db")):
        argv = ["replay", "--config", str(config), str(archive), "--into", str(tmp_path / into)]
        assert main([*argv, *engine]) == 0
        assert "4 analysed" in capsys.readouterr().out
        with open_history(tmp_path / into) as h:
            fits = h.diagnostic_fits("m1", settings.key())
            runs = {r.id: r.recording_sha256 for r in h.runs("m1")}
        assert len(fits) == 4
        values[into] = {
            runs[i]: (f.value("backlash_x").value, f.value("backlash_x").u_value)
            for i, f in fits.items()
        }
    assert set(values["history.db"]) == set(run_ids)
    with open_history(tmp_path / "history.db") as h:
        assert {r.recording_sha256: r.id for r in h.runs("m1")} == run_ids
    # the same per-file function: the same numbers locally and on Dask
    assert set(values["history.db"]) == set(values["dask.db"])
    for sha, local in values["history.db"].items():
        assert local == pytest.approx(values["dask.db"][sha], rel=1e-9)
    assert sorted(v for v, _ in values["history.db"].values()) == pytest.approx(
        [(BACKLASH_UM + d) * 1e-6 for d in range(4)], abs=0.1e-6
    )
    # everything stored: a second replay skips every file
    assert main(["replay", "--config", str(config), str(archive)]) == 0
    assert "4 skipped" in capsys.readouterr().out


def test_every_diagnostic_is_made_of_sizes_its_effect_declares():
    from imu_square.monitor.diagnostics.catalog import CATALOG
    from imu_square.simulate.effects import SIZE, effect_parameters

    for effect, diagnostics in CATALOG.items():
        sizes = {p.name for p in effect_parameters(effect) if p.role == SIZE}
        for d in diagnostics:
            assert d.effect == effect and d.alarm_field == f"{d.name}_{d.suffix}"
            assert {name for name, _ in d.terms} <= sizes, (d.name, sizes)


def test_a_diagnostic_whose_nights_scatter_is_designed_on_student_s_t():
    import numpy as np
    from scipy import stats

    from imu_square.monitor.config import AlarmSettings
    from imu_square.monitor.diagnostics.alarms import design_diagnostic_alarm, design_inputs
    from imu_square.monitor.diagnostics.baseline import diagnostic_baseline

    (backlash,) = [d for d in diagnostics_of(["backlash"]) if d.name == "backlash_x"]
    alarms = AlarmSettings(monte_carlo_nights=100_000)
    # six nights whose scatter (1 µm) dwarfs their own u (0.01 µm): sigma has 5 dof
    values = 1e-6 * np.array([2.1, 0.4, 1.3, -0.6, 0.9, 2.4])
    scattered = diagnostic_baseline(values, [1e-8] * 6)
    assert scattered.nu == pytest.approx(5.0, rel=1e-3)
    # nights that agree within their u: the normal
    assert diagnostic_baseline([2e-6, 2e-6 + 1e-9], [1e-8] * 2).nu is None
    t_design = design_diagnostic_alarm(design_inputs(backlash, scattered, 3e-6, alarms))
    normal = design_diagnostic_alarm(
        {**design_inputs(backlash, scattered, 3e-6, alarms), "nu": None}
    )
    assert t_design.nu == pytest.approx(5.0, rel=1e-3) and normal.nu is None
    # a night's false alarm on its true law: the normal design on t(5) nights would fire
    # its Shewhart chart 55 times as often as designed; the t design keeps to the design
    p_t = 2 * stats.t.sf(t_design.shewhart.limit, 5)
    p_normal = 2 * stats.norm.sf(normal.shewhart.limit)
    p_wrong = 2 * stats.t.sf(normal.shewhart.limit, 5)
    assert p_t < 3 * p_normal < p_wrong / 10
    for t_chart, n_chart in zip(t_design.charts, normal.charts, strict=True):
        assert t_chart.limit > n_chart.limit


BACKLASH_ONLY = '\n[diagnostics]\neffects = ["backlash"]\n' + ALARMED
NO_VALUE = "the diagnostic fit failed: removed for the test"


@pytest.fixture(scope="module")
def unfitted(tmp_path_factory):
    """Two monitor folders of one machine with the backlash fitted, ``(first, second)``.

    first: a 3-night baseline fitted with our own trajectory's motion, then a night
    whose backlash_x the fit gave no value for. second: its copy, then a new
    baseline of 3 nights stored without diagnostics, as an older history's, and a
    night after it also without.
    """
    import sqlite3

    first = tmp_path_factory.mktemp("unfitted-first")
    config = _folder(first, BACKLASH_ONLY)
    runs = [str(backlash_night(first, d)) for d in range(3)]
    assert main(["baseline", "set", "--config", str(config), *runs]) == 0
    assert judge(config, backlash_night(first, 3))[1]["run_id"] == 4
    with sqlite3.connect(first / "history.db") as db:
        db.execute(
            "UPDATE diagnostics SET value = NULL, u_value = NULL, missing_reason = ? WHERE "
            "name = 'backlash_x' AND fit_id = (SELECT id FROM diagnostic_fits WHERE run_id = 4)",
            (NO_VALUE,),
        )
    db.close()
    second = tmp_path_factory.mktemp("unfitted-second")
    copy_base(first, second)
    bare = second / "bare.toml"  # the same machine and history, no diagnostics
    bare.write_text(MONITOR.format(program=second / "program.toml"))
    runs = [str(backlash_night(second, d)) for d in (10, 11, 12)]
    assert main(["baseline", "set", "--config", str(bare), *runs]) == 0
    assert judge(bare, backlash_night(second, 13))[1]["run_id"] == 8
    return first, second


def _history_with_linuxcnc_motion(folder, capsys):
    """``imu-square history`` of a folder's monitor file, its motion LinuxCNC's: the lines."""
    lc = folder / "linuxcnc.toml"
    lc.write_text(
        (folder / "monitor.toml")
        .read_text()
        .replace("[program]\n", '[program]\nmotion = "linuxcnc"\n')
    )
    capsys.readouterr()
    assert main(["history", "--config", str(lc)]) == 0
    return capsys.readouterr().out.splitlines()


def _alarm_cell(report, name):
    """The alarm cell of a diagnostic's row in the report's diagnostics table, as text."""
    import html
    import re

    section = report.split('<section id="diagnostics">')[1].split("</section>")[0]
    row = re.search(rf"<tr><td class='text'>{name}</td>(.*?)</tr>", section).group(1)
    return html.unescape(re.findall(r"<td[^>]*>(.*?)</td>", row)[-1])


def test_a_diagnostic_without_a_baseline_under_another_motion_says_why(unfitted, capsys):
    # The baseline's nights were fitted with our own trajectory's motion; judged with
    # LinuxCNC's (nightly --motion linuxcnc), no diagnostic has a baseline, and the
    # report and history say why next to the alarm's state, which is not "off".
    from imu_square.monitor.config import read_monitor
    from imu_square.monitor.night import judge_history
    from imu_square.monitor.report.html import render_report

    folder = unfitted[0]
    config = read_monitor(folder / "monitor.toml")
    with open_history(folder / "history.db") as h:
        trajectory = judge_history(config, h)
        linuxcnc = judge_history(config.with_motion("linuxcnc"), h)
    why = (
        "no baseline: 0 of the baseline's 3 nights have a diagnostic fit under these "
        "settings with the motion 'linuxcnc'"
    )
    assert [t.baseline for t in linuxcnc.diagnostics] == [None, None]
    assert all(t.note.startswith(why) for t in linuxcnc.diagnostics)
    report = render_report(linuxcnc)
    # backlash_x's alarm was asked for: not judged, and why; backlash_y's was not: off
    assert _alarm_cell(report, "backlash_x") == f"not judged; {linuxcnc.diagnostics[0].note}"
    assert _alarm_cell(report, "backlash_y") == f"off; {linuxcnc.diagnostics[1].note}"
    # with the motion the baseline ran, backlash_x is judged and has no note
    assert all(t.baseline is not None and t.note == "" for t in trajectory.diagnostics)
    assert _alarm_cell(render_report(trajectory), "backlash_y") == "off"
    # history, the monitor file's motion LinuxCNC's: every night and the baseline unfitted
    out = _history_with_linuxcnc_motion(folder, capsys)
    assert (
        "4 judged night(s) have no diagnostic fit under these settings with the motion "
        "'linuxcnc' (runs 1, 2, 3, 4): replay their recordings ('imu-square replay') with them"
    ) in out
    assert f"every diagnostic: {linuxcnc.diagnostics[0].note}" in out


def test_nights_without_a_value_or_a_fit_are_marked_on_the_charts_bottom_edge(unfitted):
    # backlash_x has no value on run 4; runs 5 to 8 (the current baseline's nights and
    # the night after) have no fit. Each is an x on the backlash panel's bottom edge,
    # never on a value.
    import matplotlib

    matplotlib.use("Agg")
    import numpy as np
    from matplotlib import pyplot as plt

    from imu_square.monitor.config import read_monitor
    from imu_square.monitor.history.encoding import datetime_from_ns
    from imu_square.monitor.night import judge_history
    from imu_square.monitor.report.diagnostics_figure import plot_diagnostics

    folder = unfitted[1]
    with open_history(folder / "history.db") as h:
        assessment = judge_history(read_monitor(folder / "monitor.toml"), h)
    when = {n.run.id: datetime_from_ns(n.run.recorded_at_ns) for n in assessment.nights}
    drawn = {}

    def savefig(fig, *args, **kwargs):
        fig.canvas.draw()  # the limits as they are in the file
        (ax,) = fig.axes
        for line in ax.lines:
            if line.get_marker() == "x":
                xy = line.get_transform().transform(
                    np.column_stack([ax.convert_xunits(line.get_xdata()), line.get_ydata()])
                )
                drawn[line.get_label()] = (list(line.get_xdata()), xy[:, 1], ax.bbox.y0)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(plt.Figure, "savefig", savefig)
        plot_diagnostics(assessment, folder / "diagnostics.png")
    assert drawn  # every x on the bottom edge, whatever the limits became
    for _, y, bottom in drawn.values():
        np.testing.assert_allclose(y, bottom, atol=1e-6)  # display pixels
    assert set(drawn) == {"backlash_x: no value", "backlash_y: no value"}
    for name, runs in (("backlash_x", [4, 5, 6, 7, 8]), ("backlash_y", [5, 6, 7, 8])):
        assert drawn[f"{name}: no value"][0] == [when[i] for i in runs]


def test_history_says_which_nights_have_no_diagnostic_fit(unfitted, capsys):
    # the current baseline's nights have no fit (an older history): said in one line,
    # and why no diagnostic has a baseline
    folder = unfitted[1]
    capsys.readouterr()
    assert main(["history", "--config", str(folder / "monitor.toml")]) == 0
    out = capsys.readouterr().out.splitlines()
    assert (
        "4 judged night(s) have no diagnostic fit under these settings with the motion "
        "'trajectory' (runs 5, 6, 7, 8): replay their recordings ('imu-square replay') with them"
    ) in out
    assert (
        "every diagnostic: no baseline: 0 of the baseline's 3 nights have a diagnostic fit "
        "under these settings with the motion 'trajectory' (a fit is kept under the settings "
        "and motion it ran with): replay their recordings ('imu-square replay') with them, or "
        "set a new baseline"
    ) in out
