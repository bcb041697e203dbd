"""NC code generation: the path a control would run equals the program's circle test."""

import itertools
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
from gcode_check import RADIUS_TOLERANCE_MM, parse_nc
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from imu_square.cli import main
from imu_square.errors import ProgramError
from imu_square.program import TestProgram, program_from_mapping
from imu_square.program.ncgen import (
    DEFAULT_APPROACH_MM,
    DIALECTS,
    START_DWELL_S,
    block_arcs_deg,
    generate_nc,
)

# Coordinates are written with 3 decimals (1 um): a rounded point is within
# 0.5e-3 * sqrt(2) mm of the true one. The centre (start point + rounded I/J)
# is within that of the true centre, so the radius is within twice that.
COORD_TOL_MM = 0.5e-3 * math.sqrt(2) + 1e-9
RADIUS_TOL_MM = 2 * COORD_TOL_MM


def angle_tol(program):
    """Bound on one arc's angle error from rounded end points and centre. [rad]"""
    return 4 * COORD_TOL_MM / (program.radius_m * 1e3) + 1e-12


@st.composite
def programs(draw):
    """Valid programs: one feed, or two or three feeds with their own cycle counts."""
    r = draw(st.floats(5.0, 1000.0))
    n_feeds = draw(st.sampled_from([1, 1, 2, 3]))
    # feeds from plausible centripetal accelerations, each a factor 1.2-4 below
    # the previous one, capped at 1.99 m/s, so that every draw is a valid program
    accs = [draw(st.floats(0.05, 19.0))]
    for _ in range(n_feeds - 1):
        accs.append(max(accs[-1] / draw(st.floats(1.2, 4.0)), 0.006))
    feeds = [min(math.sqrt(a * r * 1e-3), 1.99) * 6e4 for a in accs]
    assume(all(f1 >= 1.06 * f2 for f1, f2 in itertools.pairwise(feeds)))
    cycles = [draw(st.integers(2, 6)) for _ in feeds]
    table = {
        "radius_mm": r,
        "cycles_per_direction": cycles if n_feeds > 1 else cycles[0],
        "overshoot_deg": draw(
            st.one_of(st.sampled_from([0.0, 90.0, 180.0, 360.0]), st.floats(0.0, 360.0))
        ),
        "start_angle_deg": draw(st.floats(-720.0, 720.0)),
        "order": draw(st.sampled_from([["ccw", "cw"], ["cw", "ccw"], ["ccw", "cw", "cw", "ccw"]])),
        "dwell_s": draw(st.sampled_from([0.0, 0.25, 2.0] if n_feeds == 1 else [0.5, 2.0])),
        "runs": draw(st.integers(1, 3)),
        "centre_mm": [draw(st.floats(-500.0, 500.0)), draw(st.floats(-500.0, 500.0))],
    }
    if n_feeds > 1:
        table["feeds_mm_per_min"] = feeds
    else:
        table["feed_mm_per_min"] = feeds[0]
    return program_from_mapping(table)


def split_blocks(trace):
    """Events between the START and END marker comments of each block."""
    blocks = []
    current = None
    for event in trace.events:
        if event.kind == "comment" and event.text.startswith("IMU-SQUARE START"):
            assert current is None
            current = {"tag": event.text.removeprefix("IMU-SQUARE START "), "events": []}
        elif event.kind == "comment" and event.text.startswith("IMU-SQUARE END"):
            assert current is not None and event.text.endswith(current["tag"])
            blocks.append(current)
            current = None
        elif current is not None:
            current["events"].append(event)
    assert current is None
    return blocks


def check_path(program, trace, marker_mcode=None):
    """Assert the parsed program runs the test the program describes."""
    cx, cy = (c * 1e3 for c in program.centre_m)
    r_mm = program.radius_m * 1e3
    feeds = [v * 6e4 for v in program.feeds]
    plans = program.blocks()
    blocks = split_blocks(trace)
    assert len(blocks) == len(plans)

    rapid, lead_in = trace.of_kind("rapid"), trace.of_kind("feed")
    assert len(rapid) == 1 and len(lead_in) == 1
    assert lead_in[0].value == pytest.approx(feeds[0], abs=1e-3)
    start = (
        cx + r_mm * math.cos(program.start_angle_rad),
        cy + r_mm * math.sin(program.start_angle_rad),
    )
    assert math.dist(lead_in[0].end, start) <= COORD_TOL_MM
    approach = min(DEFAULT_APPROACH_MM, r_mm / 2)
    assert math.dist(rapid[0].end, start) == pytest.approx(approach, abs=2 * COORD_TOL_MM)

    for plan, block in zip(plans, blocks, strict=True):
        tag = f"BLOCK {plan.index} RUN {plan.run} {plan.direction.upper()}"
        if program.n_feeds > 1:
            tag += f" FEED {feeds[plan.feed]:g}"
        assert block["tag"] == tag
        arcs = [e for e in block["events"] if e.kind == "arc"]
        assert [e.kind for e in block["events"] if e.kind != "arc"] == (
            ["mcode", "mcode"] if marker_mcode is not None else []
        )
        if marker_mcode is not None:
            assert block["events"][0].kind == "mcode" and block["events"][-1].kind == "mcode"
            assert block["events"][0].value == marker_mcode
        assert all(a.sign == plan.sign for a in arcs)
        for a in arcs:
            assert math.dist(a.centre, (cx, cy)) <= COORD_TOL_MM
            assert a.radius_mm == pytest.approx(r_mm, abs=RADIUS_TOL_MM)
            assert a.value == pytest.approx(feeds[plan.feed], abs=1e-3)
        total = sum(a.angle_rad for a in arcs)
        tol = len(arcs) * angle_tol(program)
        assert total == pytest.approx(program.at_feed(plan.feed).block_angle_rad, abs=tol)
        # the block starts at its planned angle
        a0 = math.atan2(arcs[0].start[1] - cy, arcs[0].start[0] - cx)
        assert math.remainder(a0 - plan.start_angle_rad, 2 * math.pi) == pytest.approx(
            0.0, abs=angle_tol(program)
        )

    # block 0 starts from rest: a dwell right after the lead-in feed move, then
    # the dwells between blocks
    dwells = trace.of_kind("dwell")
    expected = [max(program.dwell_s, START_DWELL_S)]
    expected += [program.dwell_s] * (len(plans) - 1) if program.dwell_s > 0 else []
    assert [d.value for d in dwells] == pytest.approx(expected, abs=5e-4)
    first = trace.events.index(dwells[0])
    assert trace.events[first - 1] == lead_in[0]
    assert trace.events[first + 1].text.startswith("IMU-SQUARE START BLOCK 0")
    for d in dwells[1:]:
        before = [e for e in trace.events if e.line < d.line and e.kind == "comment"][-1]
        assert before.text.startswith("IMU-SQUARE END")


@pytest.mark.parametrize("dialect", DIALECTS)
@settings(max_examples=25, deadline=None)
@given(program=programs())
def test_generated_path_matches_program(dialect, program):
    text = generate_nc(program, dialect)
    check_path(program, parse_nc(text, dialect))


@pytest.mark.parametrize("dialect", DIALECTS)
def test_paper_program_with_markers(dialect):
    program = TestProgram(dwell_s=2.0, runs=2)
    mcode = 101 if dialect == "linuxcnc" else 250
    trace = parse_nc(generate_nc(program, dialect, marker_mcode=mcode), dialect)
    check_path(program, trace, marker_mcode=mcode)
    # 180 deg overshoot: every arc is a full circle, 16 per block (180 + 15*360 + 180)
    arcs = trace.of_kind("arc")
    assert len(arcs) == 4 * 16
    assert all(a.angle_rad == 2 * math.pi and a.start == a.end for a in arcs)
    assert len(trace.of_kind("mcode")) == 2 * program.n_blocks
    assert len([e for e in trace.of_kind("comment") if "IMU-SQUARE START" in e.text]) == 4


@pytest.mark.parametrize(
    ("overshoot", "arcs"),
    [
        (0.0, [180.0, 360.0, 180.0]),
        (90.0, [270.0, 360.0, 270.0]),
        (180.0, [360.0, 360.0, 360.0]),
        (270.0, [225.0, 225.0, 360.0, 225.0, 225.0]),
        (360.0, [270.0, 270.0, 360.0, 270.0, 270.0]),
    ],
)
def test_block_arcs_never_shorter_than_half_circle(overshoot, arcs):
    program = TestProgram(cycles_per_direction=2, overshoot_rad=math.radians(overshoot))
    assert block_arcs_deg(program) == arcs
    assert sum(arcs) == pytest.approx(math.degrees(program.block_angle_rad), rel=1e-12)


@pytest.mark.parametrize(
    ("dialect", "preamble", "dwell", "end"),
    [
        ("linuxcnc", "G21 G17 G90 G91.1 G94 G40 G49 G80 G64", "G4 P2.000", "M2"),
        ("fanuc", "G21 G17 G90 G94 G40 G49 G80 G64", "G4 X2.000", "M30"),
        ("sinumerik", "G71 G17 G90 G94 G40 G64", "G4 F2.000", "M30"),
    ],
)
def test_dialect_words(dialect, preamble, dwell, end):
    lines = generate_nc(TestProgram(), dialect).splitlines()
    # continuous-path mode explicitly, before any motion
    assert preamble in lines
    assert lines.index(preamble) < next(i for i, line in enumerate(lines) if line.startswith("G0"))
    # before block 0 (max(2 s, START_DWELL_S)) and between the two blocks
    assert lines.count(dwell) == 2
    assert end in lines
    if dialect == "sinumerik":
        assert not any("(" in line for line in lines)
    else:
        assert not any(";" in line for line in lines)
    if dialect == "fanuc":
        assert lines[0] == "%" and lines[-1] == "%"


def test_linuxcnc_marker_needs_a_user_mcode_file_says_the_header():
    lines = generate_nc(TestProgram(), "linuxcnc", marker_mcode=123).splitlines()
    preamble = next(i for i, line in enumerate(lines) if line.startswith("G21"))
    assert any("M123" in line and "USER M-CODE PATH" in line for line in lines[:preamble])
    assert "USER M-CODE" not in generate_nc(TestProgram(), "linuxcnc")


def test_feed_override_lock_linuxcnc_only():
    text = generate_nc(TestProgram(), "linuxcnc", feed_override_safe=True)
    lines = text.splitlines()
    first_arc = next(i for i, line in enumerate(lines) if line.startswith("G3"))
    assert lines.index("M50 P0") < first_arc
    assert lines.index("M50 P1") > max(i for i, line in enumerate(lines) if line.startswith("G2"))
    parse_nc(text, "linuxcnc")
    with pytest.raises(ProgramError, match=r"fanuc has no standard code.*got 'fanuc'"):
        generate_nc(TestProgram(), "fanuc", feed_override_safe=True)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"dialect": "heidenhain"}, r"dialect must be one of .*got 'heidenhain'"),
        ({"dialect": "linuxcnc", "marker_mcode": 30}, r"100-199, got 30"),
        ({"dialect": "fanuc", "marker_mcode": 30}, r"not one of .*got 30"),
        ({"dialect": "sinumerik", "marker_mcode": 1000}, r"1-999.*got 1000"),
        ({"dialect": "fanuc", "marker_mcode": True}, r"whole number, got True"),
        ({"dialect": "fanuc", "approach_mm": 150.0}, r"approach_mm must be in \(0, .*got 150.0"),
    ],
)
def test_bad_generator_options(kwargs, match):
    with pytest.raises(ProgramError, match=match):
        generate_nc(TestProgram(), **kwargs)


@pytest.mark.parametrize(
    ("dialect", "text", "match"),
    [
        ("fanuc", "G21 G17 G90\nG0 X1 Y1 ; hi\nM30\n", "comment syntax not allowed in fanuc"),
        ("sinumerik", "G71 G17 G90\n(hi)\nM30\n", "comment syntax not allowed"),
        ("linuxcnc", "G17 G90 G64\nG0 X1 Y1\nM2\n", r"motion before \['G21'\]"),
        ("linuxcnc", "G21 G17 G90\nG0 X1 Y1\nM2\n", r"motion before \['G64'\]"),
        ("fanuc", "G21 G17 G90 G61\nG0 X1 Y1\nM30\n", "one motion or dwell G-code"),
        ("sinumerik", "G71 G17 G90\nG0 X1 Y1\nM30\n", r"motion before \['G64'\]"),
        ("linuxcnc", "G21 G17 G90 G64\nG1 X1 Y1\nM2\n", "feed move before any F"),
        ("linuxcnc", "G21 G17 G90 G64\nG0 X1 Y0\nG3 X-1.1 Y0 I-1 J0 F10\nM2\n", "end radius"),
        ("fanuc", "G21 G17 G90\nG4 P2.0\nM30\n", "fanuc dwell is 'G4 X<seconds>'"),
        ("linuxcnc", "G21 G17 G90 G64\nG0 X1 Y1 Z3\nM2\n", "G0 takes X, Y"),
        ("linuxcnc", "G21 G17 G90 G64\nG0 X1 Y1\n", "no M2 program end"),
        ("linuxcnc", "G21 G17 G90\nM2\nG0 X1 Y1\n", "nothing may follow the program end"),
        ("linuxcnc", "G21 G17 G90 G0 X1 Y1 X2\nM2\n", "a word letter repeats"),
    ],
)
def test_checker_is_strict(dialect, text, match):
    with pytest.raises(ProgramError, match=match):
        parse_nc(text, dialect)


def test_cli_writes_nc_and_prints_timing(tmp_path, capsys):
    toml = tmp_path / "p.toml"
    toml.write_text(TestProgram(runs=2).to_toml())
    out = tmp_path / "warmup.nc"
    argv = ["program", str(toml), "--dialect", "sinumerik", "-o", str(out), "--marker-mcode", "77"]
    assert main(argv) == 0
    said = capsys.readouterr()
    assert "period 6.283 s" in said.out and "4 blocks of 100.53 s" in said.out  # the result
    assert f"wrote {out}" in said.err
    trace = parse_nc(out.read_text(), "sinumerik")
    check_path(TestProgram(runs=2), trace, marker_mcode=77)


def test_cli_bad_marker_is_one_line_error(tmp_path, capsys):
    toml = tmp_path / "p.toml"
    toml.write_text(TestProgram().to_toml())
    argv = ["program", str(toml), "-o", str(tmp_path / "w.nc"), "--marker-mcode", "5"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()  # the timing went to stdout
    assert len(err) == 1 and "linuxcnc must be a user M-code in 100-199, got 5" in err[0]
    assert not (tmp_path / "w.nc").exists()


# ---- the real LinuxCNC interpreter (rs274ngc, through its Python `gcode` module) ----

_CANON_SCRIPT = r"""
import json, sys
import gcode

events = []

class Canon:
    parameter_file = ""
    def __getattr__(self, name):
        if name.startswith("__"):
            raise AttributeError(name)
        return lambda *args: events.append([name, *args])
    def next_line(self, state): pass
    def check_abort(self): return False
    def get_external_angular_units(self): return 1.0
    def get_external_length_units(self): return 1.0
    def get_axis_mask(self): return 7
    def get_block_delete(self): return False
    def get_tool(self, n): return (n,) + (0,) * 13

result, last = gcode.parse(sys.argv[1], Canon(), "G21", "G17")
json.dump({"result": result, "last": last, "events": events}, sys.stdout)
"""


def _linuxcnc_env():
    """Environment that lets a subprocess import LinuxCNC's `gcode`, or None."""
    root = Path(os.environ.get("IMU_SQUARE_LINUXCNC_ROOT", "/"))
    dist = root / "usr/lib/python3/dist-packages"
    if not list(dist.glob("gcode.cpython-*.so")):
        return None
    env = dict(os.environ)
    env["PYTHONPATH"] = str(dist)
    env["LD_LIBRARY_PATH"] = str(root / "usr/lib")
    return env


def run_linuxcnc(path):
    env = _linuxcnc_env()
    if env is None:
        pytest.skip(
            "LinuxCNC's interpreter is not installed: apt-get install linuxcnc-uspace (or "
            "set IMU_SQUARE_LINUXCNC_ROOT to a copy unpacked with dpkg-deb -x)"
        )
    proc = subprocess.run(
        [sys.executable, "-c", _CANON_SCRIPT, str(path)],
        capture_output=True,
        text=True,
        env=env,
        cwd=path.parent,  # the interpreter writes its rs274ngc.var parameter file here
        timeout=60,
        check=False,
    )
    cannot_load = ("cannot open shared object", "ImportError", "ModuleNotFoundError")
    if proc.returncode != 0 and any(m in proc.stderr for m in cannot_load):
        # e.g. a missing libboost-python, or a Python other than the 3.11 it was built for
        pytest.skip(f"LinuxCNC's interpreter cannot load: {proc.stderr.strip()[-200:]}")
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


INCH_MM = 25.4  # the interpreter's canonical calls are in inches


@pytest.mark.parametrize(
    "program",
    [
        TestProgram(cycles_per_direction=3, runs=2, dwell_s=1.5, centre_m=(0.2, -0.05)),
        TestProgram(
            radius_m=0.05,
            feed_m_per_s=0.05,
            cycles_per_direction=2,
            overshoot_rad=math.radians(37.5),
            start_angle_rad=math.radians(-100.0),
            order=("cw", "ccw"),
            centre_m=(-0.3, 0.12),
        ),
        TestProgram(cycles_per_direction=2, overshoot_rad=math.radians(300.0)),
        TestProgram(
            radius_m=0.025,
            feeds_m_per_s=(0.4, 0.15),
            cycles_per_feed=(6, 3),
            runs=2,
            dwell_s=1.0,
            centre_m=(0.1, 0.1),
        ),
    ],
)
def test_linuxcnc_interpreter_runs_the_test(tmp_path, program):
    path = tmp_path / "warmup.ngc"
    path.write_text(generate_nc(program, "linuxcnc", marker_mcode=101, feed_override_safe=True))
    check_interpreted(program, run_linuxcnc(path))


@settings(max_examples=8, deadline=None)
@given(program=programs())
def test_linuxcnc_interpreter_runs_any_program(tmp_path_factory, program):
    path = tmp_path_factory.mktemp("nc") / "warmup.ngc"
    path.write_text(generate_nc(program, "linuxcnc", marker_mcode=199))
    check_interpreted(program, run_linuxcnc(path))


def check_interpreted(program, out):
    """Assert the interpreter's canonical calls run the program's circle test."""
    # 1 = INTERP_EXIT: the interpreter reached M2 without an error
    assert out["result"] == 1, out
    cx, cy = (c * 1e3 for c in program.centre_m)
    r_mm = program.radius_m * 1e3
    pos = None
    blocks = []
    start_dwell = []
    previous = None
    feed = None
    for name, *args in out["events"]:
        if name in ("straight_traverse", "straight_feed"):
            pos = (args[0] * INCH_MM, args[1] * INCH_MM)
        elif name == "comment" and args[0].startswith("IMU-SQUARE START"):
            blocks.append({"angle": 0.0, "rot": set(), "markers": [], "feeds": set()})
        elif name == "dwell" and not blocks:
            start_dwell.append((previous, args[0]))
        elif name == "user_defined_function":
            assert args[0] in (1, 99)  # M101, M199 = user M-code 100 + n
            blocks[-1]["markers"].append(blocks[-1]["angle"])
        elif name == "dwell":
            blocks[-1]["dwell_after"] = args[0]
        elif name == "set_feed_rate" and args[0] > 0:
            feed = args[0] * INCH_MM
        elif name == "arc_feed":
            blocks[-1]["feeds"].add(feed)
            x1, y1, acx, acy = (a * INCH_MM for a in args[:4])
            rot = args[4]
            assert math.dist((acx, acy), (cx, cy)) <= COORD_TOL_MM
            assert math.hypot(x1 - acx, y1 - acy) == pytest.approx(r_mm, abs=RADIUS_TOL_MM)
            sign = 1 if rot > 0 else -1
            a0 = math.atan2(pos[1] - acy, pos[0] - acx)
            a1 = math.atan2(y1 - acy, x1 - acx)
            turns = abs(rot) - 1
            partial = (sign * (a1 - a0)) % (2 * math.pi)
            if math.dist(pos, (x1, y1)) < 1e-9:
                partial = 2 * math.pi  # LinuxCNC: end == start is one full turn
            blocks[-1]["angle"] += partial + 2 * math.pi * turns
            blocks[-1]["rot"].add(sign)
            pos = (x1, y1)
        previous = name
    # block 0 starts from rest: the lead-in feed move, a dwell, then block 0
    assert start_dwell == [("straight_feed", pytest.approx(max(program.dwell_s, START_DWELL_S)))]
    plans = program.blocks()
    assert len(blocks) == len(plans)
    for plan, block in zip(plans, blocks, strict=True):
        assert block["rot"] == {plan.sign}
        # every arc of the block at the block's feed (F is written with 3 decimals)
        assert len(block["feeds"]) == 1
        assert block["feeds"].pop() == pytest.approx(program.feeds[plan.feed] * 6e4, abs=5e-4)
        block_angle = program.at_feed(plan.feed).block_angle_rad
        tol = len(block_arcs_deg(program, plan.feed)) * angle_tol(program)
        assert block["markers"] == pytest.approx([0.0, block_angle], abs=tol)
        assert block["angle"] == pytest.approx(block_angle, abs=tol)
    dwells = [b["dwell_after"] for b in blocks[:-1] if "dwell_after" in b]
    expected = [program.dwell_s] * (len(plans) - 1) if program.dwell_s > 0 else []
    assert dwells == pytest.approx(expected, abs=5e-4)


def test_radius_tolerance_matches_linuxcnc():
    # LinuxCNC rejects an arc whose end radius differs by more than 0.0005 in.
    assert RADIUS_TOLERANCE_MM <= 0.0005 * INCH_MM


def test_linuxcnc_interpreter_rejects_a_bad_arc(tmp_path):
    # positive control: the interpreter really checks arcs (end radius 1.1 vs 1)
    path = tmp_path / "bad.ngc"
    path.write_text("G21 G17 G90\nG0 X1 Y0\nG3 X-1.1 Y0 I-1 J0 F100\nM2\n")
    out = run_linuxcnc(path)
    assert out["result"] > 1
    assert not [e for e in out["events"] if e[0] == "arc_feed"]
