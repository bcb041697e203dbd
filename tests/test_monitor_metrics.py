"""The Prometheus text file: checked by Prometheus's own promtool, escaping, atomic replacement."""

import datetime as dt
import re
import shutil
import stat
import subprocess
import tempfile
import threading
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from imu_square.errors import MonitorConfigError, MonitorError
from imu_square.monitor.alerts.alert import STATES
from imu_square.monitor.report import metrics
from imu_square.monitor.report.metrics import (
    MetricsSnapshot,
    metrics_from_mapping,
    render_metrics,
    write_metrics,
)
from imu_square.units import URAD

PROMTOOL = shutil.which("promtool")
needs_promtool = pytest.mark.skipif(
    PROMTOOL is None,
    reason="promtool is not installed (Debian: apt-get install --no-install-recommends prometheus)",
)

LAST = dt.datetime(2026, 10, 3, 2, 14, 5, 120000, tzinfo=dt.UTC)
FULL = MetricsSnapshot(
    machine_id="mill-3",
    state="alarm",
    runs=42,
    invalid_runs=3,
    change_rad=14.2 * URAD,
    u_change_rad=3.1 * URAD,
    eps_c_rad=0.0123,
    u_eps_c_rad=0.0004,
    last_run_at=LAST,
    last_valid_run_at=LAST - dt.timedelta(days=1),
)

_SAMPLE = re.compile(r'^(\w+)\{((?:\w+="(?:[^"\\]|\\.)*",?)*)\} (\S+)$')
_LABEL = re.compile(r'(\w+)="((?:[^"\\]|\\.)*)"')


def unescape(value):
    return re.sub(r"\\(.)", lambda m: {"n": "\n", '"': '"', "\\": "\\"}[m.group(1)], value)


def samples(text):
    """(name, labels, value) of every sample line: an independent reader of the format."""
    out = []
    for line in text.split("\n"):  # only LF ends a line; str.splitlines also splits at \x1e
        if not line or line.startswith("#"):
            continue
        name, labels, value = _SAMPLE.fullmatch(line).groups()
        out.append((name, {k: unescape(v) for k, v in _LABEL.findall(labels)}, float(value)))
    return out


def promtool(text):
    """promtool check metrics on ``text``: (exit code, its complaints)."""
    done = subprocess.run(
        [PROMTOOL, "check", "metrics"], input=text.encode("utf-8"), capture_output=True, timeout=30
    )
    return done.returncode, (done.stdout + done.stderr).decode("utf-8", "replace").strip()


@needs_promtool
def test_promtool_accepts_the_file_and_the_values_are_the_snapshot(tmp_path):
    path = write_metrics(tmp_path / "imu_square_mill3.prom", FULL)
    text = path.read_text()
    assert promtool(text) == (0, "")
    got = {
        (name, labels.get("state")): (labels["machine_id"], value)
        for name, labels, value in samples(text)
    }
    assert got[("imu_square_squareness_change_radians", None)] == (
        "mill-3",
        pytest.approx(14.2e-6, rel=1e-15),
    )
    assert got[("imu_square_squareness_change_uncertainty_radians", None)][1] == pytest.approx(
        3.1e-6, rel=1e-15
    )
    assert got[("imu_square_sensor_rotation_radians", None)][1] == 0.0123
    assert got[("imu_square_sensor_rotation_uncertainty_radians", None)][1] == 0.0004
    assert got[("imu_square_last_run_timestamp_seconds", None)][1] == LAST.timestamp()
    assert got[("imu_square_last_valid_run_timestamp_seconds", None)][1] == LAST.timestamp() - 86400
    assert got[("imu_square_runs_total", None)][1] == 42
    assert got[("imu_square_invalid_runs_total", None)][1] == 3
    # The state is one-hot: one series per state, 1 for the current one.
    assert {s: got[("imu_square_state", s)][1] for s in STATES} == {
        s: float(s == "alarm") for s in STATES
    }
    assert "# TYPE imu_square_runs_total counter" in text and "# HELP imu_square_state " in text


@needs_promtool
def test_values_that_do_not_exist_yet_are_left_out_not_nan(tmp_path):
    first_night = MetricsSnapshot(machine_id="mill-3", state="no_baseline", runs=1, invalid_runs=0,
                                  last_run_at=LAST)  # fmt: skip
    text = render_metrics(first_night)
    assert promtool(text) == (0, "")
    names = {name for name, _, _ in samples(text)}
    assert names == {"imu_square_state", "imu_square_last_run_timestamp_seconds",
                     "imu_square_runs_total", "imu_square_invalid_runs_total"}  # fmt: skip
    assert "NaN" not in text and "change" not in text


@needs_promtool
def test_promtool_would_catch_a_label_written_without_escaping(monkeypatch):
    # The check can fail: the same file with escaping switched off is refused.
    monkeypatch.setattr(metrics, "escape_label_value", lambda value: value)
    code, complaint = promtool(
        render_metrics(FULL.__class__(**{**FULL.__dict__, "machine_id": 'a"b'}))
    )
    assert code != 0 and "label" in complaint


# Every Unicode scalar a TOML string can hold (no lone surrogates), control characters included.
machine_ids = st.text(st.characters(blacklist_categories=("Cs",)), min_size=1, max_size=40)


@needs_promtool
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    machine_id=machine_ids
    | st.sampled_from(['a\\"b', "x\\", "\n", '"', "\\n", "mill 3 ü 測 $(id)"])
)
def test_any_machine_id_is_escaped_so_promtool_accepts_it_and_reads_it_back(machine_id):
    text = render_metrics(
        MetricsSnapshot(machine_id=machine_id, state="ok", runs=5, invalid_runs=0)
    )
    code, complaint = promtool(text)
    assert code == 0, complaint
    ids = {labels["machine_id"] for _, labels, _ in samples(text)}
    assert ids == {machine_id}


def test_the_file_is_replaced_atomically_and_readable_by_node_exporter(tmp_path):
    path = tmp_path / "imu_square.prom"
    path.write_text("old\n")
    seen = []
    stop = threading.Event()

    def reader():
        while not stop.is_set():
            seen.append(path.read_text())

    watcher = threading.Thread(target=reader)
    watcher.start()
    try:
        for runs in range(1, 60):
            write_metrics(path, MetricsSnapshot("mill-3", "ok", runs=runs, invalid_runs=0))
    finally:
        stop.set()
        watcher.join()
    # Every read saw either the old file or a whole new one, never a part.
    whole = [t for t in seen if t != "old\n"]
    assert len(seen) > 10
    assert all(t.endswith('imu_square_invalid_runs_total{machine_id="mill-3"} 0\n') for t in whole)
    assert stat.S_IMODE(path.stat().st_mode) == 0o644
    assert [p.name for p in tmp_path.iterdir()] == ["imu_square.prom"]  # no temporary file left


def test_the_temporary_file_is_never_a_prom_file(tmp_path, monkeypatch):
    # node_exporter reads every *.prom in its folder: a half-written one must not be one.
    names = []
    real = tempfile.mkstemp

    def spy(*args, **kwargs):
        fd, name = real(*args, **kwargs)
        names.append(name)
        return fd, name

    monkeypatch.setattr(tempfile, "mkstemp", spy)
    write_metrics(tmp_path / "m.prom", FULL)
    (name,) = names
    assert name.startswith(str(tmp_path / ".m.prom.")) and name.endswith(".tmp")


def test_bad_snapshots_and_an_unwritable_folder_are_clear_errors(tmp_path):
    with pytest.raises(
        MonitorError, match=r"nowhere/m.prom: cannot write the metrics file: No such file"
    ):
        write_metrics(tmp_path / "nowhere" / "m.prom", FULL)
    with pytest.raises(ValueError, match="state must be one of"):
        render_metrics(MetricsSnapshot("m", "fine", runs=1, invalid_runs=0))
    with pytest.raises(ValueError, match="last_run_at must be timezone-aware"):
        render_metrics(MetricsSnapshot("m", "ok", 1, 0, last_run_at=dt.datetime(2026, 1, 1)))
    with pytest.raises(ValueError, match="runs must be a whole number >= 0"):
        render_metrics(MetricsSnapshot("m", "ok", runs=-1, invalid_runs=0))


@needs_promtool
def test_shell_metacharacters_in_the_machine_id_and_path_are_data(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    machine = "$(touch pwned) `touch pwned`; touch pwned | touch pwned\n'\"\\ ü"
    path = tmp_path / "$(touch pwned);`touch pwned`|touch pwned ü.prom"
    write_metrics(path, MetricsSnapshot(machine, "warning", runs=2, invalid_runs=1))
    text = path.read_text()
    assert promtool(text) == (0, "")
    assert {labels["machine_id"] for _, labels, _ in samples(text)} == {machine}
    assert not (tmp_path / "pwned").exists()


def test_the_metrics_section_of_the_monitor_file():
    assert metrics_from_mapping(None).textfile is None
    config = metrics_from_mapping({"textfile": "m.prom"}, "monitor.toml", "/var/lib/ne")
    assert config.textfile == Path("/var/lib/ne/m.prom")
    with pytest.raises(
        MonitorConfigError,
        match=r"\[metrics\] textfile must be a file name ending in '.prom'.*got 'm.txt'",
    ):
        metrics_from_mapping({"textfile": "m.txt"}, "monitor.toml")
    with pytest.raises(MonitorConfigError, match=r"\[metrics\] has unknown field 'path'"):
        metrics_from_mapping({"path": "m.prom"}, "monitor.toml")
    with pytest.raises(
        MonitorConfigError, match=r"\[metrics\] is missing the required field 'textfile'"
    ):
        metrics_from_mapping({}, "monitor.toml")


def test_the_user_guide_lists_the_metrics_the_file_holds_with_their_types():
    guide = Path(__file__).resolve().parents[1] / "docs" / "user-guide" / "alerts-metrics.md"
    documented = {}
    for names, kind in re.findall(
        r"^\| (`imu_square_.*?) \| (gauge|counter) \|", guide.read_text(), re.M
    ):
        for name in re.findall(r"`(imu_square_\w+)", names):
            documented[name] = kind
    text = render_metrics(FULL)
    written = dict(re.findall(r"^# TYPE (\w+) (\w+)$", text, re.M))
    assert documented == written
    assert {name for name, _, _ in samples(text)} == set(written)
