"""The main job end to end: emulated board -> pty -> recorder -> MCAP -> analysis -> plot."""

import json

import pytest

from imu_square.cli import main

PROGRAM = """[program]
radius_mm = 25.0
feed_mm_per_min = 9000.0
cycles_per_direction = 10
dwell_s = 1.0
"""


def test_nightly_on_the_emulated_board_recovers_the_truth(tmp_path, capsys):
    program = tmp_path / "p.toml"
    program.write_text(PROGRAM)
    out = tmp_path / "out"
    code = main(
        [
            "nightly",
            "--program",
            str(program),
            "--speed",
            "20",
            "--seed",
            "3",
            "--out",
            str(out),
            "--json",
        ]
    )
    captured = capsys.readouterr()
    assert code == 0, captured.err
    result = json.loads(captured.out.strip().splitlines()[-1])
    stems = sorted(p.name for p in out.iterdir())
    assert any(s.endswith(".png") for s in stems) and any(s.endswith(".truth.json") for s in stems)
    assert result["recording_complete"] is True
    assert result["cycles_used"] == {"ccw": 10, "cw": 10}
    # The simulator's truth lies within three standard uncertainties of the result.
    assert abs(result["error_urad"]) <= 3 * result["u_squareness_urad"]
    # The built-in typical machine has 0.5 ms of servo mismatch: m = omega * 0.5 ms.
    assert abs(result["servo_mismatch_urad"] - 6.0 * 0.5e-3 * 1e6) <= 3 * 200
    assert "truth (simulator)" in captured.err


TWO_FEEDS = """[program]
radius_mm = 25.0
feeds_mm_per_min = [9000.0, 4500.0]
cycles_per_direction = [10, 5]
dwell_s = 1.0
"""


@pytest.mark.slow
def test_nightly_with_two_feeds_separates_gravity(tmp_path, capsys):
    program = tmp_path / "p.toml"
    program.write_text(TWO_FEEDS)
    out = tmp_path / "out"
    code = main(
        [
            "nightly",
            "--program",
            str(program),
            "--speed",
            "10",
            "--seed",
            "4",
            "--out",
            str(out),
            "--json",
        ]
    )
    captured = capsys.readouterr()
    assert code == 0, captured.err
    result = json.loads(captured.out.strip().splitlines()[-1])
    assert [f["feed_mm_per_min"] for f in result["feeds"]] == [9000.0, 4500.0]
    assert [f["cycles_used"] for f in result["feeds"]] == [
        {"ccw": 10, "cw": 10},
        {"ccw": 5, "cw": 5},
    ]
    # the truth freed of gravity coupling lies within three standard uncertainties
    assert abs(result["error_urad"]) <= 3 * result["u_squareness_urad"]
    assert "freed of gravity coupling" in captured.err
