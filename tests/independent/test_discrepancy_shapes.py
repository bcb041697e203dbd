"""The discrepancy workflow on effects in shapes and signs this generator chose.

A representative subset of ``benchmarks/discrepancy_independent.py``'s
acceptance set (issue 22, section 3), on a short circle at 200 Hz so that the
whole module runs in well under a minute: each effect with a candidate is
named in a shape ``simulate/`` does not use (the generator's spikes centred on
or led by a compensation pulse, inward or outward; over-compensated lost
motion through a play operator; a first-order servo lag), a clean recording
names nothing, an effect with no candidate of its shape leaves a headline that
says a gap is left, and every headline obeys the rule of section 2
(:func:`~imu_square.discrepancy.result.headline_is_honest`).
"""

import math

import pytest
from generator import generate

from imu_square.discrepancy import DiscrepancyOptions, find_discrepancy
from imu_square.discrepancy.result import headline_is_honest
from imu_square.program.spec import TestProgram

SHORT = TestProgram(radius_m=0.05, feed_m_per_s=0.05, cycles_per_direction=4, dwell_s=1.0)
SENSOR = {"rate_hz": 200.0, "eps_c_rad": math.radians(2.1)}
ALPHA = {"squareness_rad": 50e-6}
# Lost motion of X (Y has 0.7 of it): 4.0x the backlash candidate's detection limit on
# this test (the benchmark's 50 %-power noncentrality of its 2-dof test). [m]
LOST_M = 40e-9


def _spikes(shape, height):
    return [
        {"axis": "x", "shape": shape, "height_m": height, "width_s": 0.01},
        {"axis": "y", "shape": shape, "height_m": 0.7 * height, "width_s": 0.01},
    ]


def _run(effects, seed=1):
    rec, _ = generate(SHORT, {**ALPHA, **effects}, SENSOR, seed=seed)
    result = find_discrepancy(rec, DiscrepancyOptions(suggest=False))
    doc = result.to_json_dict()
    assert headline_is_honest(doc), doc["headline"]
    named = set(result.named_effects) | {e for g in result.ambiguous for e in g}
    return result, named


NAMED = {
    "spikes centred, inward": ({"spikes": _spikes("centred", -1.5e-6)}, "reversal_spikes"),
    "spikes led by compensation, outward": ({"spikes": _spikes("led", 1.5e-6)}, "reversal_spikes"),
    "spikes after, inward": ({"spikes": _spikes("after", -2e-6)}, "reversal_spikes"),
    "servo first-order lag of y": ({"servo_y": {"tau_s": 3e-3}}, "servo_mismatch"),
    # a play operator engaging through a 150 Hz contact, the table thrown ahead: named
    # reversal_spikes alone before the take-up's timing was scanned as finely as the spike's
    "lost motion over-compensated, 150 Hz contact": (
        {
            "lost_motion_x": {"lost_motion_m": -LOST_M, "engagement_hz": 150.0},
            "lost_motion_y": {"lost_motion_m": -0.7 * LOST_M, "engagement_hz": 150.0},
        },
        "backlash",
    ),
}


@pytest.mark.parametrize("case", list(NAMED))
def test_an_effect_in_a_shape_we_did_not_write_is_named(case):
    effects, candidate = NAMED[case]
    _, named = _run(effects)
    assert candidate in named, named


def test_a_clean_recording_names_nothing_and_says_it_is_explained():
    result, named = _run({}, seed=4)
    assert not named
    assert result.explained and result.headline().startswith("the base model explains")


def test_an_effect_with_no_candidate_leaves_a_gap_in_the_headline():
    # a ball-screw lead error: no candidate has its shape
    result, _ = _run({"cyclic_x": {"amplitude_m": 2e-6, "pitch_m": 0.01}})
    assert not result.explained
    assert "gap is left" in result.headline() and "NOT" in result.headline()
    where = {g.view: g for g in result.gap_left}
    assert where, result.headline()
    # the gap's band: harmonics of the circle near v / pitch (5 Hz here), not the circle's own
    bands = [g.details["band"]["band_hz"] for g in result.gap_left if "band" in g.details]
    assert any(lo <= 5.0 * 1.6 and hi >= 5.0 / 1.6 for lo, hi in bands), bands


# --------------------------------------------------------------------------- known disagreements


@pytest.mark.xfail(
    strict=True,
    raises=AssertionError,
    reason="a mode rung by the feed ramps at block starts rings in the overshoot, "
    "which no view looks at: every view reads the noise and the headline says explained",
)
def test_known_ringing_at_block_starts_leaves_a_gap():
    mode = {"freq_hz": 41.0, "zeta": 0.05, "participation": 0.05}
    result, _ = _run({"mode_x": mode, "mode_y": dict(mode)})
    assert not result.explained
