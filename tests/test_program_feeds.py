"""A program that runs the same circle at several feeds: file, timing, NC code, simulator."""

import itertools
import math

import numpy as np
import pytest
from gcode_check import parse_nc
from program_timeline import nominal_angle

from imu_square.cli import main
from imu_square.errors import ProgramError
from imu_square.program import parse_program, program_from_mapping
from imu_square.program.ncgen import DIALECTS, generate_nc
from imu_square.simulate import MachineModel, SensorModel, simulate_run
from imu_square.simulate.truth import gravity_coupling_rad_per_m
from imu_square.units import G

TWO = {
    "radius_mm": 50.0,
    "feeds_mm_per_min": [6000.0, 3000.0],
    "cycles_per_direction": [6, 3],
    "dwell_s": 1.0,
}


def with_(**changes):
    table = dict(TWO)
    table.update(changes)
    return table


def test_two_feeds_run_one_after_the_other():
    p = program_from_mapping(TWO)
    assert p.n_feeds == 2
    assert p.feeds == pytest.approx((0.1, 0.05), rel=1e-15)
    assert p.feed_cycles == (6, 3)
    plans = p.blocks()
    assert [(b.feed, b.direction, b.run) for b in plans] == [
        (0, "ccw", 0),
        (0, "cw", 0),
        (1, "ccw", 0),
        (1, "cw", 0),
    ]
    # block angle 2*pi*cycles + 2*pi (two 180 deg overshoots), at omega = v / r
    fast = 2 * math.pi * 7 / 2.0
    slow = 2 * math.pi * 4 / 1.0
    assert [b.duration_s for b in plans] == pytest.approx([fast, fast, slow, slow], rel=1e-14)
    assert plans[2].t_start_s == pytest.approx(2 * fast + 2 * 1.0, rel=1e-14)
    assert p.duration_s == pytest.approx(2 * fast + 2 * slow + 3 * 1.0, rel=1e-14)
    # each block starts where the previous one ended
    for a, b in itertools.pairwise(plans):
        end = nominal_angle(p, a, a.t_end_s)
        assert b.start_angle_rad == pytest.approx(end, rel=1e-14)


def test_each_feed_is_a_one_feed_program_of_its_blocks():
    p = program_from_mapping(with_(runs=2, start_angle_deg=30.0))
    for f, speed in enumerate((0.1, 0.05)):
        sub = p.at_feed(f)
        assert sub.n_feeds == 1 and sub.feed_m_per_s == pytest.approx(speed, rel=1e-15)
        assert sub.cycles_per_direction == (6, 3)[f]
        mine = [b for b in p.blocks() if b.feed == f]
        for ours, theirs in zip(mine, sub.blocks(), strict=True):
            assert theirs.start_angle_rad == pytest.approx(ours.start_angle_rad, rel=1e-14)
            assert theirs.duration_s == pytest.approx(ours.duration_s, rel=1e-14)
            assert (theirs.direction, theirs.run) == (ours.direction, ours.run)
    # a list of one feed is a one-feed program
    one = {"radius_mm": 50.0, "cycles_per_direction": 6}
    listed = program_from_mapping({**one, "feeds_mm_per_min": [6000.0]})
    assert listed == program_from_mapping({**one, "feed_mm_per_min": 6000.0})
    assert listed.n_feeds == 1 and listed.at_feed(0) is listed


def test_toml_round_trip_of_two_feeds():
    p = program_from_mapping(TWO)
    text = p.to_toml()
    assert "feeds_mm_per_min = [6000.0, 3000.0]" in text
    assert "cycles_per_direction = [6, 3]" in text
    assert "feed_mm_per_min" not in text.replace("feeds_mm_per_min", "")
    assert parse_program(text) == p
    same = program_from_mapping(with_(cycles_per_direction=[5, 5]))
    assert "cycles_per_direction = 5\n" in same.to_toml()
    assert parse_program(same.to_toml()) == same


@pytest.mark.parametrize(
    "name", ["omega_rad_s", "period_s", "centripetal_m_s2", "block_angle_rad", "block_duration_s"]
)
def test_a_one_circle_quantity_of_two_feeds_is_refused(name):
    p = program_from_mapping(TWO)
    with pytest.raises(ProgramError, match=rf"^{name}: the program runs 2 feeds \(6000, 3000 mm"):
        getattr(p, name)


@pytest.mark.parametrize(
    ("table", "match"),
    [
        (
            with_(feed_mm_per_min=6000.0),
            r"needs exactly one of 'feed_mm_per_min' .* and 'feeds_mm_per_min' .*got both",
        ),
        (
            {k: v for k, v in TWO.items() if k != "feeds_mm_per_min"},
            r"needs exactly one of .*got neither",
        ),
        (with_(feeds_mm_per_min=[]), r"feeds_mm_per_min must be a list of 1 to 8 feeds.*got \[\]"),
        (with_(feeds_mm_per_min=6000.0), r"must be a list of 1 to 8 feeds .*got 6000\.0"),
        (with_(feeds_mm_per_min=[6000.0, "x"]), r"feeds_mm_per_min must be a number, got 'x'"),
        (with_(feeds_mm_per_min=[6000.0, -1.0]), r"feeds_mm_per_min must be in \(0, 120000\]"),
        (
            with_(feeds_mm_per_min=[6000.0, 5800.0]),
            r"must differ from each other by at least 5% .*got \[6000\.0, 5800\.0\]",
        ),
        (
            with_(cycles_per_direction=[6, 3, 2]),
            r"cycles_per_direction must be one whole number, or a list of one per feed \(2\)",
        ),
        (with_(cycles_per_direction=[6, 1]), r"cycles_per_direction must be .*\[2, 1000\], got 1"),
        (with_(dwell_s=0.2), r"dwell_s must be at least 0\.5 s with several feeds.*got 0\.2"),
        (
            with_(feeds_mm_per_min=[6000.0, 100.0]),
            r"feeds_mm_per_min=100 with radius_mm=50 gives a centripetal acceleration of "
            r"5\.56e-05 m/s\^2; .* needs 0\.005 to 20 m/s\^2",
        ),
    ],
)
def test_bad_feeds_name_field_value_and_allowed(table, match):
    with pytest.raises(ProgramError, match=match):
        program_from_mapping(table, source="p.toml")


@pytest.mark.parametrize("dialect", DIALECTS)
def test_nc_code_runs_each_feed_with_its_cycles(dialect):
    p = program_from_mapping(with_(runs=2))
    trace = parse_nc(generate_nc(p, dialect, marker_mcode=150), dialect)
    starts = [e.text for e in trace.of_kind("comment") if e.text.startswith("IMU-SQUARE START")]
    assert starts[0] == "IMU-SQUARE START BLOCK 0 RUN 0 CCW FEED 6000"
    assert starts[-1] == "IMU-SQUARE START BLOCK 7 RUN 1 CW FEED 3000"
    arcs = trace.of_kind("arc")
    # 180 deg overshoots: (cycles + 1) full circles per block, 4 blocks per feed
    assert len(arcs) == 4 * 7 + 4 * 4
    assert [a.value for a in arcs] == [6000.0] * 28 + [3000.0] * 16
    assert sum(a.angle_rad for a in arcs) == pytest.approx(2 * math.pi * 44, rel=1e-9)


def test_program_command_prints_each_feed(tmp_path, capsys):
    path = tmp_path / "p.toml"
    path.write_text(program_from_mapping(TWO).to_toml())
    assert main(["program", str(path), "-o", str(tmp_path / "w.ngc")]) == 0
    err = capsys.readouterr().out  # the timing is the command's result
    assert "r=50 mm, 2 feeds" in err
    assert "6000 mm/min: period 3.142 s, 2 blocks of 21.99 s" in err
    assert "3000 mm/min: period 6.283 s, 2 blocks of 25.13 s" in err
    parse_nc((tmp_path / "w.ngc").read_text(), "linuxcnc")


def block_phase_diff(recording, block, omega):
    """psi_y - psi_x of one block's analysed cycles, minus the nominal quadrature. [rad]"""
    t = recording.time_s
    accel = recording.accel.astype(float)
    period = 2 * math.pi / omega
    t0 = block["analysed_start_s"]
    n_cycles = math.floor((block["analysed_end_s"] - t0) / period + 1e-9)
    m = (t >= t0) & (t < t0 + n_cycles * period)
    design = np.column_stack([np.cos(omega * t[m]), np.sin(omega * t[m]), np.ones(m.sum())])
    psi = []
    for k in range(2):
        (c, s, _), *_ = np.linalg.lstsq(design, accel[m, k], rcond=None)
        psi.append(math.atan2(-s, c))
    nominal = -math.pi / 2 if block["direction"] == "ccw" else math.pi / 2
    return math.remainder(psi[1] - psi[0] - nominal, 2 * math.pi)


def test_simulator_runs_each_feed_with_its_own_truth():
    # noise-free, gravity coupling on all four gradients and servo lags: each feed's
    # blocks show -D - m (CCW) and +D - m (CW) in the time domain with that feed's D
    # (gravity phase ~ 1/A) and m = omega (tau_y - tau_x)
    program = program_from_mapping(with_(cycles_per_direction=[3, 2], runs=1))
    machine = MachineModel(tilt_per_m=(1e-4, 2e-4, -1e-4, 3e-4), tau_x_s=2e-3, tau_y_s=3e-3)
    eps = math.radians(3.0)
    sensor = SensorModel(sample_rate_hz=200.0, eps_c_rad=eps, beta_rad=30e-6)
    rec, truth = simulate_run(program, machine, sensor, seed=0)
    assert [b["feed"] for b in truth["blocks"]] == [0, 0, 1, 1]
    assert [f["feed_mm_per_min"] for f in truth["feeds"]] == pytest.approx([6000.0, 3000.0])
    kappa = gravity_coupling_rad_per_m(machine, eps)
    assert truth["gravity_coupling_rad_per_m"] == kappa
    for f, ft in enumerate(truth["feeds"]):
        a = program.at_feed(f).centripetal_m_s2
        assert ft["amplitude_m_s2"] == pytest.approx(a, rel=1e-15)
        ccw, cw = (
            block_phase_diff(rec, b, ft["omega_rad_s"]) for b in truth["blocks"] if b["feed"] == f
        )
        d, m = 0.5 * (cw - ccw), -0.5 * (ccw + cw)
        assert d == pytest.approx(ft["expected_squareness_rad"], abs=0.1e-6)
        # m cos(2 eps) to first order; the lag also turns the gravity term, a cross term
        # of order m * g r k / A ~ 2e-7 rad here
        assert m == pytest.approx(ft["servo_mismatch_rad"] * math.cos(2 * eps), abs=0.5e-6)
        # to first order the gravity coupling adds (g r / A) kappa; the rest is of
        # second order in g r k / A (up to 3e-3 rad here)
        q = G * program.radius_m / a
        gravity = ft["expected_squareness_rad"] - truth["expected_squareness_gravity_free_rad"]
        assert gravity == pytest.approx(q * kappa, abs=(q * 3e-4) ** 2)
    assert truth["expected_squareness_rad"] == truth["feeds"][0]["expected_squareness_rad"]


def test_info_shows_each_feed(tmp_path, capsys):
    from imu_square.io.mcap import write_mcap

    program = program_from_mapping(with_(cycles_per_direction=[3, 2]))
    rec, _ = simulate_run(program, MachineModel(), SensorModel(sample_rate_hz=100.0), seed=0)
    path = tmp_path / "two.mcap"
    write_mcap(rec, path)
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "feeds 6000 mm/min (period 3.142 s), 3000 mm/min (period 6.283 s)" in out
