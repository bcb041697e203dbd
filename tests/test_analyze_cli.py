"""``imu-square analyze`` end to end: MCAP files in, summary, JSON lines and a plot out."""

import json
from pathlib import Path

import numpy as np
import pytest
from pipeline_synth import synth_circle

from imu_square.cli import main
from imu_square.io.mcap import write_mcap
from imu_square.program import TestProgram, read_program
from imu_square.units import G

PROG = TestProgram(cycles_per_direction=3, dwell_s=1.0)
REALDATA = Path("/work/shared/realdata/Inkering__printnoser__rectangle_1__accel.csv")


def _write(tmp_path, name, **kw):
    rec, truth = synth_circle(PROG, fs=100.0, **kw)
    path = tmp_path / name
    write_mcap(rec, path)
    return path, truth


@pytest.mark.slow
def test_json_lines_summary_and_plot(tmp_path, capsys):
    runs = [
        _write(tmp_path, f"run{i}.mcap", alpha=60e-6, density=1e-6, seed=i)[0] for i in range(3)
    ]
    png = tmp_path / "out.png"
    code = main(["analyze", *map(str, runs), "--json", "--plot", str(png), "--bootstrap", "20"])
    out, err = capsys.readouterr()
    assert code == 0
    docs = [json.loads(line) for line in out.strip().splitlines()]
    assert len(docs) == 3
    for doc in docs:
        # CRB for 6 cycles at 1e-6 m/s^2/rtHz is ~2.3 urad.
        assert doc["squareness_urad"] == pytest.approx(60.0, abs=12.0)
        assert doc["cycles_used"] == {"ccw": 3, "cw": 3}
    assert docs[-1]["convergence"]["n_runs"] == [1, 2, 3]
    assert docs[0]["convergence"]["u_mean_urad"] == [None]
    assert "squareness" in err and "µm/m" in err and "eps_c" in err
    assert "after 3 runs: mean" in err
    assert png.stat().st_size > 20_000


def test_options_reach_the_analysis(tmp_path, capsys):
    path, _ = _write(tmp_path, "run.mcap", density=1e-6)
    code = main(
        ["analyze", str(path), "--json", "--cutoff-hz", "2", "--order", "2", "--bootstrap", "0"]
    )
    doc = json.loads(capsys.readouterr().out)
    assert code == 0
    assert doc["options"]["cutoff_hz"] == 2.0 and doc["options"]["order"] == 2
    assert doc["u_squareness_bootstrap_urad"] is None


def test_bad_run_is_one_line_and_the_others_still_count(tmp_path, capsys):
    good, _ = _write(tmp_path, "good.mcap", density=1e-6)
    bad, _ = _write(tmp_path, "bad.mcap", scale=4.0)
    code = main(["analyze", str(bad), str(good), "--json", "--bootstrap", "0"])
    out, err = capsys.readouterr()
    assert code == 2
    assert len(out.strip().splitlines()) == 1
    error_lines = [line for line in err.splitlines() if "error" in line]
    assert error_lines == [
        f"imu-square analyze: error: {bad}: measured 0.40 m/s² but the program implies "
        "0.10 m/s²: check the feed, the radius or the units"
    ]


def test_quality_warnings_are_shown(tmp_path, capsys):
    slow = TestProgram(cycles_per_direction=3, dwell_s=1.0, feed_m_per_s=0.099)
    rec, _ = synth_circle(slow, fs=100.0)
    rec.program = PROG
    path = tmp_path / "slow.mcap"
    write_mcap(rec, path)
    assert main(["analyze", str(path), "--bootstrap", "0"]) == 0
    err = capsys.readouterr().out  # the result, with its warnings
    assert "warning: circle period differs from the program by +1.01%" in err


def test_real_rectangle_through_import_and_analyze(tmp_path, capsys):
    if not REALDATA.exists():
        pytest.skip(f"{REALDATA} is not available")
    program = tmp_path / "circle.toml"
    program.write_text(
        "[program]\nradius_mm = 100.0\nfeed_mm_per_min = 6000.0\ncycles_per_direction = 2\n"
        "overshoot_deg = 0.0\ndwell_s = 2.0\n"
    )
    mcap = tmp_path / "rect.mcap"
    cols = "t_s,ax_mps2,ay_mps2,az_mps2"
    assert (
        main(
            [
                "import",
                str(REALDATA),
                "--program",
                str(program),
                "-o",
                str(mcap),
                "--columns",
                cols,
                "--relative-time",
            ]
        )
        == 0
    )
    capsys.readouterr()
    assert main(["analyze", str(mcap)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "no circular motion matching the program" in err[0]


def test_a_run_given_twice_counts_once(tmp_path, capsys):
    # the same samples twice (by path or by a copy) would count one run twice in the mean
    # of runs and shrink its type A uncertainty by sqrt(2)
    good, _ = _write(tmp_path, "good.mcap", density=1e-6)
    copy = tmp_path / "copy.mcap"
    copy.write_bytes(good.read_bytes())
    code = main(["analyze", str(good), str(good), str(copy), "--json", "--bootstrap", "0"])
    out, err = capsys.readouterr()
    assert code == 2
    docs = [json.loads(line) for line in out.strip().splitlines()]
    assert [d["recording"] for d in docs] == [str(good)]
    assert docs[0]["convergence"]["n_runs"] == [1]
    errors = [line for line in err.splitlines() if "error" in line]
    assert errors == [
        f"imu-square analyze: error: recordings: {good} and {second} hold the same samples: "
        "give each run once (a run counted twice would halve its variance)"
        for second in (good, copy)
    ]
    assert "after 2 runs" not in err


@pytest.mark.parametrize("n", ["1", "-5"])
def test_a_bootstrap_of_fewer_than_two_resamples_is_refused(tmp_path, capsys, n):
    # One resample has no spread (numpy's "Degrees of freedom <= 0" warnings and a NaN
    # u); a negative count used to skip the bootstrap silently.
    path, _ = _write(tmp_path, "run.mcap")
    assert main(["analyze", str(path), "--bootstrap", n]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err.strip().splitlines() == [
        f"imu-square analyze: error: bootstrap_n must be 0 (no bootstrap) or at least 2, got {n}"
    ]


def test_one_clipped_sample_after_a_stop_moves_no_time_anchor(tmp_path, capsys):
    # Four blocks of 4 circles (r 25 mm at 9000 mm/min: 0.955 Hz, v^2/r = 0.9 m/s^2),
    # eps_c 1 deg, 7 µg/√Hz at 500 Hz, written to CSV and imported with a 2 g range.
    # One sample at +2 g on x 78 ms after the first CW block stops: low-passed to
    # 2.6 m/s^2 it stood above the motion threshold (0.45 m/s^2) and moved that
    # block's detected stop by 0.1 s, eps_c to 4.9 +- 1.5 deg and the floor 3.7 times.
    toml = tmp_path / "p.toml"
    toml.write_text(
        "[program]\nradius_mm = 25.0\nfeed_mm_per_min = 9000.0\ncycles_per_direction = 4\n"
        "dwell_s = 2.0\nruns = 2\n"
    )
    eps_c = np.radians(1.0)
    rec, truth = synth_circle(
        read_program(toml), eps_c=eps_c, ramp_s=0.15, density=7e-6 * G, fs=500.0, seed=3
    )
    spike = round((truth["blocks"][1]["t1"] + 0.078) * 500.0)
    docs = {}
    for name, at in (("clean", []), ("clipped", [spike])):
        accel = rec.accel.copy()
        accel[at, 0] = 2 * G
        csv = tmp_path / f"{name}.csv"
        np.savetxt(
            csv,
            np.column_stack([rec.time_s, accel]),
            fmt="%.9f",
            delimiter=",",
            header="time_s,accel_x,accel_y,accel_z",
            comments="",
        )
        mcap = tmp_path / f"{name}.mcap"
        argv = ["import", str(csv), "--program", str(toml), "-o", str(mcap), "--range-g", "2"]
        assert main([*argv, "--start-time", "2026-11-01T02:00:00Z"]) == 0
        capsys.readouterr()
        assert main(["analyze", "--json", str(mcap)]) == 0
        out, err = capsys.readouterr()
        docs[name] = (json.loads(out), err)
    doc, err = docs["clipped"]
    clean = docs["clean"][0]
    assert doc["quality"]["clipped_samples"] == 1
    assert (
        f"1 sample(s) at the sensor's full scale (clipping), at {rec.time_s[spike]:.3f} s: "
        "left out as lost" in err
    )
    # The sample lies in no analysed cycle: all 8 + 8 are kept, eps_c is within its
    # u (0.07 deg) of the truth, and the residual, so the floor, is the clean run's.
    assert doc["cycles_used"] == {"ccw": 8, "cw": 8}
    assert abs(doc["eps_c_deg"] - 1.0) < doc["u_eps_c_deg"]
    assert doc["crb_urad"] == pytest.approx(clean["crb_urad"], rel=0.02)
    assert doc["squareness_urad"] == pytest.approx(
        clean["squareness_urad"], abs=0.1 * doc["u_squareness_urad"]
    )
