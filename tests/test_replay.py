"""``imu-square replay``: a folder of 100 recordings (3 of them corrupt) into fresh
histories with one local process, two, and a Dask LocalCluster: the same rows and the
same verdicts every way, an injected degradation's alarm night, idempotence,
interruption, other analysis settings compared with ``history --compare``.
"""

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest
from monitor_rig import ALPHA, SENSOR, START

from imu_square.cli import main
from imu_square.io.mcap import write_mcap
from imu_square.monitor.history.store import open_history
from imu_square.monitor.replay import ReplayJob, expand_paths, run_dask
from imu_square.program import program_from_mapping
from imu_square.simulate.geometry import Geometry
from imu_square.simulate.machine import MachineModel
from imu_square.simulate.run import simulate_run

PROGRAM = program_from_mapping(
    {"radius_mm": 25.0, "feed_mm_per_min": 9000.0, "cycles_per_direction": 4, "dwell_s": 0.3}
)
N_FILES, STEP_NIGHT, STEP = 100, 70, 15e-6
MONITOR = """\
[monitor]
machine_id = "m1"
history = "history.db"

[program]
file = "program.toml"

[analysis]
bootstrap = 0

[alarms]
monte_carlo_nights = 200000

# a replay's diagnostics: tests/test_monitor_diagnostics.py (here 300 fits would cost minutes)
[diagnostics]
effects = []
"""


def _archive(folder):
    """100 nights, the squareness 15 µm/m up from night 70; nights 13, 41, 88 corrupt."""
    (folder / "program.toml").write_text(PROGRAM.to_toml())
    (folder / "monitor.toml").write_text(MONITOR)
    data = folder / "archive" / "2026"
    data.mkdir(parents=True)
    for day in range(N_FILES):
        alpha = ALPHA + (STEP if day >= STEP_NIGHT else 0.0)
        machine = MachineModel(geometry=Geometry(machine_squareness_rad=alpha))
        when = START + timedelta(days=day)
        path = data / f"m1-{day:03d}.mcap"
        if day in (13, 41, 88):
            path.write_bytes(b"\x89MCAP0\r\n" if day == 13 else b"junk" * (day + 1))
            continue
        rec, _ = simulate_run(
            PROGRAM, machine, SENSOR, seed=day, t0_ns=int(when.timestamp() * 1e9), lead_in_s=0.5
        )
        write_mcap(rec, path)
    return folder


@pytest.fixture(scope="module")
def archive(tmp_path_factory):
    return _archive(tmp_path_factory.mktemp("replay"))


def _replay(archive, *extra):
    code = main(["replay", "--config", str(archive / "monitor.toml"), *extra])
    assert code == 0


def _rows(location):
    """Every run and its verdict, as comparable values (ids and analysis times aside)."""
    with open_history(location) as h:
        states = {e.run_id: (e.state, e.change_rad, e.u_change_rad, e.statistics)
                  for e in h.evaluations("m1")}  # fmt: skip
        out = {}
        for r in h.runs("m1"):
            row = {k: v for k, v in vars(r).items() if k not in ("id", "analysed_at_ns")}
            out[r.recording_sha256] = (json.dumps(row, sort_keys=True), states.get(r.id))
        return out


@pytest.mark.slow
def test_the_same_history_whatever_the_engine_and_the_alarm_night(archive, capsys):
    folder = str(archive / "archive")
    # the machine's own history: replay, set the baseline from its first 5 nights, judge
    _replay(archive, folder, "--jobs", "2")
    out = capsys.readouterr()
    # the 3 corrupt files cannot be read: failed, never stored as runs
    assert "97 analysed, 0 skipped (already stored), 0 invalid, 3 failed" in out.out
    with open_history(archive / "history.db") as h:
        first = [r.id for r in h.runs("m1", valid_only=True)][:5]
    assert main(["baseline", "set", "--config", str(archive / "monitor.toml"),
                 *map(str, first)]) == 0  # fmt: skip
    capsys.readouterr()
    _replay(archive, folder, "--jobs", "2", "--json")  # everything is stored: judge only
    out = capsys.readouterr()
    summary = json.loads(out.out.splitlines()[-1])
    assert summary["counts"] == {"analysed": 0, "invalid": 0, "skipped": 97, "failed": 3}
    fired = summary["alarm_nights"]
    assert fired, "a 15 µm/m step (6 sigma) must be found"
    # Four cycles a night give u 3 degrees of freedom: the design (Student's t) finds a
    # 15 µm/m step after 3 nights (median), 90 % within 5 (design_alarms' check).
    first_alarm = (START + timedelta(days=STEP_NIGHT)).strftime("%Y-%m-%d")
    last_alarm = (START + timedelta(days=STEP_NIGHT + 4)).strftime("%Y-%m-%d")
    assert first_alarm <= fired[0][:10] <= last_alarm, fired
    assert all(night[:10] >= first_alarm for night in fired), "no false alarm before the step"
    # fresh histories of the first 40 nights with one process, two, and Dask: identical
    # rows and verdicts
    first40 = str(archive / "archive" / "2026" / "m1-0[0-3]?.mcap")
    histories = []
    for engine in (["--jobs", "1"], ["--jobs", "2"], ["--cluster", "local", "--jobs", "2"]):
        into = archive / f"history-{'-'.join(engine).replace('--', '')}.db"
        _replay(archive, first40, "--into", str(into), *engine)
        capsys.readouterr()
        histories.append(_rows(into))
    assert len(histories[0]) == 39  # the first 40 nights but the corrupt one (13)
    assert histories[0] == histories[1] == histories[2]
    # and the rows of the machine's own history for those nights, replayed in one go
    reference = _rows(archive / "history.db")
    assert all(reference[k][0] == row for k, (row, _) in histories[0].items())


@pytest.mark.slow
def test_other_settings_into_another_history_and_compare(archive, capsys):
    other = archive / "other.toml"
    # half the default cutoff (24 Hz at this 0.95 Hz circle), a second order
    other.write_text("[analysis]\ncutoff_hz = 12.0\norder = 2\nbootstrap = 0\n")
    plain, into = archive / "plain.db", archive / "cutoff12.db"
    _replay(archive, str(archive / "archive"), "--into", str(plain))
    _replay(archive, str(archive / "archive"), "--settings", str(other), "--into", str(into))
    capsys.readouterr()
    assert main(["history", "--config", str(archive / "monitor.toml"), "--json",
                 "--compare", str(plain), str(into)]) == 0  # fmt: skip
    out = capsys.readouterr()
    pairs = [json.loads(line) for line in out.out.splitlines()]
    assert len(pairs) == N_FILES - 3  # the corrupt files are no runs
    both = [p for p in pairs if p["a_valid"] and p["b_valid"]]
    assert len(both) == 97
    # the same samples through another filter share most of their noise: the two results
    # scatter about each other by less than one night's u, and agree on average to one u
    diff = np.array([p["b_squareness_urad"] - p["a_squareness_urad"] for p in both])
    u = float(np.median([p["a_u_squareness_urad"] for p in both]))
    assert np.std(diff, ddof=1) < u and abs(np.mean(diff)) < u
    assert "97 recordings in both, 0 only in A, 0 only in B" in out.err


@pytest.mark.slow
def test_dry_run_lists_and_bad_paths_are_one_line(archive, capsys):
    _replay(archive, str(archive / "archive" / "2026" / "m1-00*.mcap"), "--dry-run")
    out = capsys.readouterr()
    assert len(out.out.splitlines()) == 10 and "would replay 10 recording(s)" in out.err
    assert main(["replay", "--config", str(archive / "monitor.toml"), "nowhere/"]) == 2
    assert "nowhere/: no recording there" in capsys.readouterr().err
    assert main(["replay", "--config", str(archive / "monitor.toml"), "--jobs", "0",
                 str(archive / "archive")]) == 2  # fmt: skip
    assert "--jobs must be a whole number >= 1, got 0" in capsys.readouterr().err
    bad = archive / "one_resample.toml"
    bad.write_text("[analysis]\nbootstrap = 1\n")
    argv = ["replay", "--config", str(archive / "monitor.toml"), "--settings", str(bad),
            "--into", str(archive / "never.db"), str(archive / "archive")]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"{bad}: [analysis] bootstrap must be 0 (no bootstrap) or a whole number" in err
    assert len(err.strip().splitlines()) == 1 and not (archive / "never.db").exists()


def _interruptible_and_yielding():
    """In the replay's process, before it starts: Ctrl-C as at a terminal, lowest priority.

    A shell without job control starts background jobs with SIGINT ignored, which
    their children inherit: pytest run with ``&`` would hand that on and the replay
    would never see the test's SIGINT. At nice 19 the replay (about 10 ms a file)
    yields the CPU to the test, whose SIGINT then comes before the last file.
    """
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    os.nice(19)


@pytest.mark.slow
def test_an_interrupted_replay_picks_up_and_loses_nothing(archive, tmp_path):
    into = tmp_path / "interrupted.db"
    script = Path(sys.executable).with_name("imu-square")
    argv = [str(script), "replay", "--config", str(archive / "monitor.toml"),
            str(archive / "archive"), "--into", str(into), "--jobs", "2", "--json"]  # fmt: skip
    proc = subprocess.Popen(
        argv,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        preexec_fn=_interruptible_and_yielding,
    )
    done = 0
    for line in proc.stdout:  # wait until some files are in, then interrupt
        event = json.loads(line)
        done += event.get("event") == "file" and event["status"] != "failed"
        if done >= 20:
            proc.send_signal(signal.SIGINT)
            break
    proc.wait(timeout=120)
    with open_history(into) as h:
        stored = len(h.runs("m1"))
    assert 20 <= stored < N_FILES - 3
    subprocess.run(argv, check=True, capture_output=True, timeout=600)
    with open_history(into) as h:
        runs = h.runs("m1")
    assert len(runs) == N_FILES - 3  # the 3 corrupt files are no runs
    assert len({r.recording_sha256 for r in runs}) == len(runs)


@pytest.mark.slow
def test_a_dask_worker_killed_mid_replay_loses_and_doubles_no_file(archive):
    from distributed import Client, LocalCluster

    paths = expand_paths([str(archive / "archive")])[:30]
    job = ReplayJob("m1")
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster:  # fmt: skip
        with Client(cluster) as client:
            pids = list(client.run(os.getpid).values())
        outcomes = []
        killer = threading.Timer(0.0, lambda: None)

        def kill_one():
            os.kill(pids[0], signal.SIGKILL)

        for outcome in run_dask(paths, job, scheduler=cluster.scheduler_address):
            outcomes.append(outcome)
            if len(outcomes) == 5:
                killer = threading.Timer(0.1, kill_one)
                killer.start()
        killer.join()
        time.sleep(0.1)
    assert sorted(o.path for o in outcomes) == sorted(paths)
    assert {o.status for o in outcomes} <= {"analysed", "invalid", "failed"}


def test_an_unreadable_file_fails_and_a_copy_is_skipped_naming_each_file_once(tmp_path, capsys):
    (tmp_path / "program.toml").write_text(PROGRAM.to_toml())
    (tmp_path / "monitor.toml").write_text(MONITOR)
    folder = tmp_path / "archive"
    folder.mkdir()
    machine = MachineModel(geometry=Geometry(machine_squareness_rad=ALPHA))
    for day in (0, 1):
        when = int((START + timedelta(days=day)).timestamp() * 1e9)
        rec, _ = simulate_run(PROGRAM, machine, SENSOR, seed=day, t0_ns=when, lead_in_s=0.5)
        write_mcap(rec, folder / f"m1-{day}.mcap")
    shutil.copy(folder / "m1-1.mcap", folder / "m1-1-copy.mcap")
    (folder / "notes.mcap").write_text("the sensor was cleaned on Tuesday\n")
    _replay(tmp_path, str(folder), "--jobs", "1", "--json")
    out = capsys.readouterr()
    summary = json.loads(out.out.splitlines()[-1])
    assert summary["counts"] == {"analysed": 2, "invalid": 0, "skipped": 1, "failed": 1}
    with open_history(tmp_path / "history.db") as h:
        assert len(h.runs("m1")) == 2, "the unreadable file is no run, the copy no second one"
    line = next(x for x in out.err.splitlines() if "notes.mcap" in x)
    assert line.count("notes.mcap") == 1 and "not an MCAP file" in line
    # a run the analysis refuses is an invalid run; compared, its missing value is a dash
    other = program_from_mapping({"radius_mm": 50.0, "feed_mm_per_min": 6000.0,
                                  "cycles_per_direction": 3, "dwell_s": 0.5})  # fmt: skip
    when = int((START + timedelta(days=2)).timestamp() * 1e9)
    write_mcap(simulate_run(other, machine, SENSOR, seed=5, t0_ns=when)[0], folder / "m1-2.mcap")
    _replay(tmp_path, str(folder), "--jobs", "1")
    _replay(tmp_path, str(folder), "--jobs", "1", "--into", str(tmp_path / "again.db"))
    capsys.readouterr()
    argv = ["history", "--config", str(tmp_path / "monitor.toml"), "--compare"]
    assert main([*argv, str(tmp_path / "history.db"), str(tmp_path / "again.db")]) == 0
    table = capsys.readouterr().out
    assert "nan" not in table and sum("  –  " in row for row in table.splitlines()) == 1
