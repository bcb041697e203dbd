"""The program file: validation messages, units, nominal timing, TOML round trip."""

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose
from program_timeline import nominal_angle, nominal_time

from imu_square.cli import main
from imu_square.errors import ProgramError
from imu_square.program.spec import (
    MAX_CENTRIPETAL_M_S2,
    MIN_CENTRIPETAL_M_S2,
    TestProgram,
    default_program,
    parse_program,
    program_from_mapping,
    read_program,
)

GOOD = {"radius_mm": 100.0, "feed_mm_per_min": 6000.0, "cycles_per_direction": 15}


def with_(**changes):
    table = dict(GOOD)
    table.update(changes)
    return table


# Each bad value: the message must name the field, the value received (repr)
# and what is allowed.
@pytest.mark.parametrize(
    ("table", "match"),
    [
        (with_(radius_mm=0), r"radius_mm must be in \(0, 1000\], got 0\.0"),
        (with_(radius_mm=-5.0), r"radius_mm must be in \(0, 1000\], got -5\.0"),
        (with_(radius_mm=1500.0), r"radius_mm must be in \(0, 1000\], got 1500\.0"),
        (with_(radius_mm="100"), r"radius_mm must be a number, got '100'"),
        (with_(radius_mm=True), r"radius_mm must be a number, got True"),
        (with_(radius_mm=math.inf), r"radius_mm must be finite, got inf"),
        (with_(feed_mm_per_min=0.0), r"feed_mm_per_min must be in \(0, 120000\], got 0\.0"),
        (with_(cycles_per_direction=1), r"cycles_per_direction must be .* in \[2, 1000\], got 1"),
        (with_(cycles_per_direction=2.5), r"cycles_per_direction must be a whole number, got 2\.5"),
        (with_(overshoot_deg=-1.0), r"overshoot_deg must be in \[0, 360\], got -1\.0"),
        (with_(overshoot_deg=360.5), r"overshoot_deg must be in \[0, 360\], got 360\.5"),
        (with_(start_angle_deg="east"), r"start_angle_deg must be a number, got 'east'"),
        (with_(plane="XZ"), r"plane must be one of \('XY',\), got 'XZ'"),
        (with_(order=["ccw", "ccw"]), r"order must list 'ccw' and 'cw'.*got \['ccw', 'ccw'\]"),
        (with_(order=["ccw", "up"]), r"order must list 'ccw' and 'cw'.*got \['ccw', 'up'\]"),
        (with_(order="ccw,cw"), r"order must list 'ccw' and 'cw'.*got 'ccw,cw'"),
        (with_(dwell_s=-0.1), r"dwell_s must be in \[0, 600\], got -0\.1"),
        (with_(runs=0), r"runs must be in \[1, 1000\], got 0"),
        (with_(centre_mm=[1.0]), r"centre_mm must be \[x, y\] in mm, got \[1\.0\]"),
        (with_(centre_mm=[1.0, "a"]), r"centre_mm must be a number, got 'a'"),
        (with_(radius_mm1=3.0), r"unknown field 'radius_mm1'; allowed: \[.*'radius_mm'"),
        ({"radius_mm": 100.0, "feed_mm_per_min": 6000.0}, r"missing .*'cycles_per_direction'"),
    ],
)
def test_bad_field_names_field_value_and_allowed(table, match):
    with pytest.raises(ProgramError, match=match):
        program_from_mapping(table, source="p.toml")
    with pytest.raises(ProgramError, match=r"^p\.toml: \[program\] "):
        program_from_mapping(table, source="p.toml")


@pytest.mark.parametrize(
    ("radius_mm", "feed", "accel"),
    [
        # v = 0.01 m/s on r = 0.1 m: 1e-3 m/s^2, below the MEMS floor
        (100.0, 600.0, 1e-3),
        # v = 2 m/s on r = 0.1 m: 40 m/s^2, more than 4 g
        (100.0, 120000.0, 40.0),
    ],
)
def test_implausible_centripetal_acceleration(radius_mm, feed, accel):
    assert not MIN_CENTRIPETAL_M_S2 <= accel <= MAX_CENTRIPETAL_M_S2
    with pytest.raises(
        ProgramError,
        match=rf"feed_mm_per_min={feed:g} with radius_mm={radius_mm:g} gives a centripetal "
        rf"acceleration of {accel:.3g} m/s\^2; .* needs 0\.005 to 20 m/s\^2",
    ):
        program_from_mapping(with_(radius_mm=radius_mm, feed_mm_per_min=feed))


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("[program\nradius_mm = 1", r"p\.toml: not valid TOML: "),
        ("[programme]\nradius_mm = 1\n", r"p\.toml: no \[program\] table"),
        ("program = 3\n", r"p\.toml: \[program\] must be a table, got 3"),
    ],
)
def test_bad_toml(text, match):
    with pytest.raises(ProgramError, match=match):
        parse_program(text, source="p.toml")


def test_missing_file(tmp_path):
    with pytest.raises(ProgramError, match=r"nope\.toml: program file not found"):
        read_program(tmp_path / "nope.toml")


def test_paper_program_timing():
    # Szipka et al. 2019: r = 100 mm, F = 6000 mm/min, 15 cycles, 180 deg overshoot
    p = default_program()
    assert p.omega_rad_s == pytest.approx(1.0, rel=1e-15)  # v / r = 0.1 / 0.1
    assert p.period_s == pytest.approx(2 * math.pi, rel=1e-15)
    assert p.centripetal_m_s2 == pytest.approx(0.1, rel=1e-15)
    # a block is 180 + 15 * 360 + 180 deg = 16 periods
    assert p.block_angle_rad == pytest.approx(32 * math.pi, rel=1e-15)
    assert p.block_duration_s == pytest.approx(16 * 2 * math.pi, rel=1e-15)
    assert p.duration_s == pytest.approx(2 * 32 * math.pi + 2.0, rel=1e-15)
    ccw, cw = p.blocks()
    assert (ccw.direction, ccw.sign, cw.direction, cw.sign) == ("ccw", 1, "cw", -1)
    assert ccw.analysed_start_rad == pytest.approx(math.pi, rel=1e-15)
    # the CW block starts where the CCW one ended, after the dwell
    assert cw.start_angle_rad == pytest.approx(32 * math.pi, rel=1e-15)
    assert cw.analysed_start_rad == pytest.approx(31 * math.pi, rel=1e-15)
    assert cw.t_start_s == pytest.approx(ccw.t_end_s + 2.0, rel=1e-15)
    assert ccw.t_mid_s == pytest.approx(16 * math.pi, rel=1e-15)


@pytest.mark.parametrize("overshoot_deg", [0.0, 45.0, 180.0, 360.0])
def test_block_length_counts_both_overshoots(overshoot_deg):
    p = program_from_mapping(
        with_(overshoot_deg=overshoot_deg, cycles_per_direction=4, runs=3, dwell_s=0.5)
    )
    expected = math.radians(4 * 360 + 2 * overshoot_deg)
    assert p.block_angle_rad == pytest.approx(expected, rel=1e-15)
    assert p.n_blocks == 6
    plans = p.blocks()
    assert [b.run for b in plans] == [0, 0, 1, 1, 2, 2]
    for b in plans:
        assert b.duration_s == pytest.approx(expected / p.omega_rad_s, rel=1e-14)
        end = nominal_angle(p, b, b.t_end_s)
        assert end - b.start_angle_rad == pytest.approx(b.sign * expected, rel=1e-14)
    assert p.duration_s == pytest.approx(6 * plans[0].duration_s + 5 * 0.5, rel=1e-14)


valid_tables = st.fixed_dictionaries(
    {
        "radius_mm": st.floats(5.0, 1000.0),
        "accel": st.floats(0.01, 19.0),
        "cycles_per_direction": st.integers(2, 1000),
        "overshoot_deg": st.floats(0.0, 360.0),
        "start_angle_deg": st.floats(-1e4, 1e4),
        "order": st.lists(st.sampled_from(["ccw", "cw"]), min_size=2, max_size=6).filter(
            lambda o: set(o) == {"ccw", "cw"}
        ),
        "dwell_s": st.floats(0.0, 600.0),
        "runs": st.integers(1, 1000),
        "centre_mm": st.lists(st.floats(-1e4, 1e4), min_size=2, max_size=2),
    }
).map(
    lambda d: {
        **{k: v for k, v in d.items() if k != "accel"},
        "feed_mm_per_min": min(math.sqrt(d["accel"] * d["radius_mm"] * 1e-3), 1.99) * 6e4,
    }
)


def assert_same_program(a, b):
    """Equal up to the mm <-> m and deg <-> rad conversions (a few ulp)."""
    for f in dataclasses.fields(TestProgram):
        va, vb = getattr(a, f.name), getattr(b, f.name)
        if isinstance(va, float):
            assert vb == pytest.approx(va, rel=4e-16, abs=1e-300), f.name
        elif f.name == "centre_m":
            assert_allclose(vb, va, rtol=4e-16, atol=0, err_msg=f.name)
        else:
            assert vb == va, f.name


@settings(max_examples=200, deadline=None)
@given(table=valid_tables)
def test_toml_round_trip(table):
    p = program_from_mapping(table)
    q = parse_program(p.to_toml())
    assert_same_program(p, q)
    # a second trip changes nothing more than the first
    assert_same_program(q, parse_program(q.to_toml()))


@settings(max_examples=200, deadline=None)
@given(table=valid_tables, frac=st.floats(0.0, 1.0), block_pick=st.integers(0, 10**6))
def test_nominal_angle_and_time_round_trip(table, frac, block_pick):
    p = program_from_mapping(table)
    # at most 50 blocks, so the check stays fast whatever runs is
    p = dataclasses.replace(p, runs=min(p.runs, 50 // len(p.order)) or 1)
    blocks = p.blocks()
    b = blocks[block_pick % len(blocks)]
    t = b.t_start_s + frac * b.duration_s
    phi = nominal_angle(p, b, t)
    # tolerance: a few ulp of the largest magnitude involved
    tol = 64 * np.finfo(float).eps * max(abs(t), abs(phi) / p.omega_rad_s, 1.0)
    assert nominal_time(p, b, phi) == pytest.approx(t, abs=tol)
    arr = np.linspace(b.t_start_s, b.t_end_s, 7)
    assert_allclose(nominal_time(p, b, nominal_angle(p, b, arr)), arr, atol=tol)
    # the angle moves at omega in the block's direction; each angle is computed from an
    # absolute time, so its rounding grows with omega * t, not with the block's span
    phi0, phi1 = nominal_angle(p, b, b.t_start_s), nominal_angle(p, b, b.t_end_s)
    tol_phi = p.omega_rad_s * tol + 64 * np.finfo(float).eps * max(abs(phi0), abs(phi1))
    assert phi1 - phi0 == pytest.approx(b.sign * p.block_angle_rad, abs=tol_phi)


def test_cli_prints_timing(tmp_path, capsys):
    path = tmp_path / "p.toml"
    path.write_text(default_program().to_toml())
    assert main(["program", str(path)]) == 0
    out = capsys.readouterr().out  # the timing is the command's result
    assert "r=100 mm, v=6000 mm/min, period 6.283 s, 2 blocks of 100.53 s, 203.1 s" in out


def test_cli_bad_program_is_one_line(tmp_path, capsys):
    path = tmp_path / "p.toml"
    path.write_text(
        "[program]\nradius_mm = 100\nfeed_mm_per_min = 6000\ncycles_per_direction = 1\n"
    )
    assert main(["program", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"imu-square program: error: {path}: [program] cycles_per_direction must be a whole "
        "number in [2, 1000], got 1"
    ]


# A whole number is an integer in every file and function (imu_square.validation):
# the program file alone took 15.0 for 15, where the monitor file refused 2.0.
@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("cycles_per_direction = 15.0", "cycles_per_direction must be a whole number, got 15.0"),
        ("cycles_per_direction = 15\nruns = 2.0", "runs must be a whole number, got 2.0"),
    ],
)
def test_a_whole_number_is_written_as_one(tmp_path, capsys, line, message):
    path = tmp_path / "p.toml"
    path.write_text(f"[program]\nradius_mm = 100\nfeed_mm_per_min = 6000\n{line}\n")
    assert main(["program", str(path)]) == 2
    err = capsys.readouterr().err
    assert err == f"imu-square program: error: {path}: [program] {message}\n"
