"""The discrepancy workflow on effects in shapes and signs this generator chose.

A representative subset of ``benchmarks/discrepancy_independent.py``'s
acceptance set (issue 22, section 3), on a short circle at 200 Hz so that the
whole module runs in well under a minute: each effect with a candidate is
named in a shape ``simulate/`` does not use (the generator's spikes centred on
or led by a compensation pulse, inward or outward; over-compensated lost
motion through a play operator; a first-order servo lag; a mode rung by its
raised-cosine feed ramps), a clean recording
names nothing, an effect with no candidate of its shape leaves a headline that
says a gap is left, and every headline obeys the rule of section 2
(:func:`~imu_square.discrepancy.result.headline_is_honest`). A friction-rung
mode at 80 Hz runs at the paper's 500 Hz (80 Hz is at the edge of the band
compared at 200 Hz): rung by a sudden flip of the friction it is named a
vibration, and deflected by a slow one it is a lost motion.
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
# The generator's spikes' width. [s]
SPIKE_WIDTH_S = 0.01


def _spikes(shape, height):
    return [
        {"axis": "x", "shape": shape, "height_m": height, "width_s": SPIKE_WIDTH_S},
        {"axis": "y", "shape": shape, "height_m": 0.7 * height, "width_s": SPIKE_WIDTH_S},
    ]


def _run(effects, seed=1, sensor=SENSOR):
    rec, _ = generate(SHORT, {**ALPHA, **effects}, sensor, seed=seed)
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


# ------------------------------------------------------------------- spikes centred on the reversal

# A centred spike (the generator's symmetric bump) of this height is 5.1x the
# candidate's detection limit on this test (the benchmark's 50 %-power noncentrality of
# its 2-dof test: 39 nm here). [m]
CENTRED_M = 2e-7
# The stick zone's bump nearest the generator's (least squares on the acceleration):
# tau = 1.26 w, largest acceleration 1.09 h / w^2 (1.8 % of the energy left over).
TAU_PER_WIDTH = 1.26
PEAK_PER_H_W2 = 1.09


@pytest.mark.parametrize("sense", [-1.0, 1.0], ids=["inward", "outward"])
def test_a_spike_centred_on_the_reversal_is_a_symmetric_reversal_spike(sense):
    height = sense * CENTRED_M
    result, named = _run({"spikes": _spikes("centred", height)})
    # not a backlash as well: the skewed bump alone left a gap that one filled
    assert named == {"reversal_spikes"}, result.headline()
    assert "reversals" not in {g.view for g in result.gap_left}, result.headline()
    (step,) = result.steps
    fitted = {p.name: p for p in step.parameters}
    assert fitted["symmetric"].value == 1.0
    # its peak on the reversal: (onset + 2) tau = 0
    onset = fitted["onset_tau"]
    assert onset.value == pytest.approx(-2.0, abs=4 * onset.u_value)
    tau = fitted["tau_ms"]
    assert tau.value == pytest.approx(TAU_PER_WIDTH * SPIKE_WIDTH_S * 1e3, rel=0.1)
    for axis, share in (("x", 1.0), ("y", 0.7)):
        peak = fitted[f"peak_{axis}_m_s2"]
        expected = PEAK_PER_H_W2 * share * height / SPIKE_WIDTH_S**2
        assert peak.value == pytest.approx(expected, abs=4 * peak.u_value)


# --------------------------------------------------------------------------- friction-rung modes

# 80 Hz is 0.4 of the 200 Hz rate, at the compared band's edge (0.45): the paper's 500 Hz.
SENSOR_500 = {**SENSOR, "rate_hz": 500.0}
# The short circle reverses at v^2 / R = 0.05 m/s^2.
REVERSAL_ACCEL = SHORT.feed_m_per_s**2 / SHORT.radius_m


def _friction_mode(hz, friction, velocity):
    mode = {
        "freq_hz": hz,
        "zeta": 0.05,
        "friction_m_s2": friction,
        "friction_velocity_m_s": velocity,
    }
    return {"mode_x": mode, "mode_y": dict(mode)}


def test_a_mode_rung_by_friction_at_80_hz_is_named_with_its_frequency():
    # the friction flips within v_s / a = 1 ms, short against the 12.5 ms period: it rings
    # the mode. 1 mm/s^2 is 4.6x this test's detection limit (the benchmark's measure).
    result, named = _run(_friction_mode(80.0, 1e-3, 5e-5), sensor=SENSOR_500)
    assert named == {"structural_vibration"}, named
    fitted = {p.name: p for p in result.model}
    hz = fitted["structural_vibration.frequency_hz"]
    # u = 0.3 Hz: the ringing lasts 1 / (zeta omega) = 40 ms, three periods, per reversal
    assert hz.value == pytest.approx(80.0, abs=4 * hz.u_value)
    assert hz.u_value < 1.0


def test_a_friction_flip_slower_than_the_mode_is_a_lost_motion():
    # the friction turns over within v_s / a = 10 ms, longer than the 80 Hz mode's
    # period: the mode follows it quasi-statically and the table deflects by
    # 2 mu / omega_n^2 = 0.16 um along tanh(t / 10 ms), the backlash candidate's shape
    # (its ringing is 0.6 % of a sudden flip's). No test can call it a vibration; at
    # this size a short reversal spike fits the same deflection nearly as well, and the
    # honest name is the backlash or "one of" the two.
    mu, velocity = 0.02, 5e-4
    effects = _friction_mode(80.0, mu, velocity)
    _, named = _run(effects, sensor=SENSOR_500)
    assert named in ({"backlash"}, {"backlash", "reversal_spikes"}), named
    # the backlash alone, fitted, has the deflection's size and take-up
    rec, _ = generate(SHORT, {**ALPHA, **effects}, SENSOR_500, seed=1)
    result = find_discrepancy(rec, DiscrepancyOptions(suggest=False, effects=("backlash",)))
    assert result.named_effects == ("backlash",), result.headline()
    fitted = {p.name: p for p in result.model}
    deflection_um = 2 * mu / (2 * math.pi * 80.0) ** 2 * 1e6
    for axis in ("x", "y"):
        assert fitted[f"backlash.{axis}_um"].value == pytest.approx(deflection_um, rel=0.25)
    take_up_ms = velocity / REVERSAL_ACCEL * 1e3
    assert fitted["backlash.take_up_ms"].value == pytest.approx(take_up_ms, rel=0.25)


# ------------------------------------------------------------------ ringing at block starts


def test_a_mode_rung_by_the_feed_ramps_is_named():
    # The generator's mode at 41 Hz, base-excited by its 0.2 s raised-cosine feed ramps, rings
    # after each start ramp and each end of motion (the transient view's windows). Its detection
    # limit here, as benchmarks/discrepancy_independent.py defines it (50 % power of a 2-dof test
    # at 0.01 / (11 x 20 shapes), lambda50 = 19.0, against lambda = 286 kappa^2 of the fit vector
    # at zeta = 0.05), is a participation of 0.26. At 0.05 it rings below what any detector can
    # see (an ideal matched one: 2.9 sigma over the whole recording, 1.0 outside the ramps);
    # this case is drawn at 3.1 times the limit.
    mode = {"freq_hz": 41.0, "zeta": 0.05, "participation": 0.8}
    result, named = _run({"mode_x": mode, "mode_y": dict(mode)})
    assert "structural_vibration" in named, result.headline()
    fitted = {v.name: v for v in result.model}
    # the ringing after the ramps, at whatever phase: its amplitude is far from zero
    in_phase = fitted["structural_vibration.start_stop_m_s2"]
    quadrature = fitted["structural_vibration.start_stop_quadrature_m_s2"]
    amplitude = math.hypot(in_phase.value, quadrature.value)
    assert amplitude > 4 * max(in_phase.u_value, quadrature.u_value)
    # the windows hold about ten periods: 2 % of frequency is a fifth of a period at their end
    hz = fitted["structural_vibration.frequency_hz"].value
    assert hz == pytest.approx(41.0, rel=0.02)


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("zeta, participation", [(0.03, 3.3), (0.08, 6.3)])
def test_a_mode_rung_by_the_feed_ramps_at_80_hz_is_named_with_its_frequency(
    seed, zeta, participation
):
    # At 80 Hz, 1 / (zeta omega) = 20-66 ms; the ringing's phase after the generator's
    # raised-cosine ramps is not that of our trapezoid's corners, and with the phase fixed
    # by them the likelihood peaked in frequency narrower than the 12 % grid: fitted 69 or
    # 83 Hz with a gap left, or not named (2 to 5 of 6 on the benchmark). Both phases are
    # fitted now. Each case is 3.0-3.5 times its detection limit here (a participation of
    # 1.0-1.04 at zeta = 0.03, 1.78-2.07 at 0.08, on these seeds: benchmarks/
    # discrepancy_independent.py's definition).
    mode = {"freq_hz": 80.0, "zeta": zeta, "participation": participation}
    result, named = _run({"mode_x": mode, "mode_y": dict(mode)}, seed=seed, sensor=SENSOR_500)
    assert named == {"structural_vibration"} and result.explained, result.headline()
    fitted = {v.name: v for v in result.model}
    hz = fitted["structural_vibration.frequency_hz"]
    damping = fitted["structural_vibration.damping_ratio"]
    assert hz.value == pytest.approx(80.0, abs=4 * hz.u_value)
    assert damping.value == pytest.approx(zeta, abs=4 * damping.u_value)


@pytest.mark.parametrize("ramp_s, shape", [(0.6, "cosine"), (1.0, "constant_accel")])
def test_a_controllers_long_feed_ramp_leaves_no_gap_at_block_starts(ramp_s, shape):
    # the model ramps in 0.15 s: a ramp four to seven times longer still runs when the
    # model's has ended, and the transient windows must start after the recording's ramp
    motion = {"ramp_s": ramp_s, "ramp_shape": shape}
    rec, _ = generate(SHORT, dict(ALPHA), SENSOR, seed=4, motion=motion)
    result = find_discrepancy(rec, DiscrepancyOptions(suggest=False))
    assert headline_is_honest(result.to_json_dict())
    assert result.explained, result.headline()
    assert not result.named_effects


@pytest.mark.parametrize("tau_s", [0.015, 0.025])
def test_a_servo_lags_exponential_ramp_tail_leaves_no_gap_at_block_starts(tau_s):
    # Both axes' servos lag the command by a first-order tau: each ramp ends in an
    # exponential tail of decay time tau, from a few hundred sigmas; 15 ms after it crossed
    # the mark it still stood at 10 e^-1 sigmas (a gap left, or structural_vibration named,
    # in every case). The windows now wait ln(20) decay times, timed on the tail itself.
    lag = {"tau_s": tau_s}
    result, named = _run({"servo_x": lag, "servo_y": dict(lag)}, sensor=SENSOR_500)
    assert result.explained and not named, result.headline()


@pytest.mark.parametrize("participation", [5.0, 10.0])
def test_a_strong_ringing_does_not_move_its_own_transient_window(participation):
    # An 80 Hz mode rung by the feed ramps, up to a few hundred sigmas per sample: it crosses
    # the ramp's mark, but in runs of one sign a half period (6 ms) long, shorter than any
    # ramp's (RUN_S). Its windows never open later than on the same recording without it (it
    # pushed them 20 ms on, past most of itself, when any sample past the mark counted); they
    # may open earlier, where the ringing cuts the ramp's last run short: by a run and a half
    # period, and by the clean tail's wait past GUARD_S (TAIL_DECAYS times its decay of
    # 5-6 ms here: up to 4 ms; 9 ms allowed).
    import numpy as np

    from imu_square.discrepancy.transients import RUN_S
    from imu_square.discrepancy.workflow import fit_base

    mode = {"freq_hz": 80.0, "zeta": 0.05, "participation": participation}
    starts = []
    for effects in ({}, {"mode_x": mode, "mode_y": dict(mode)}):
        rec, _ = generate(SHORT, {**ALPHA, **effects}, SENSOR_500, seed=3)
        problem, _, _ = fit_base(rec, SHORT)
        layout = problem.model.layout
        index = layout.index[layout.n_analysed :]
        starts.append(index[np.r_[0, np.flatnonzero(np.diff(index) != 1) + 1]])
    clean, rung = starts
    assert rung.size == clean.size == 2 * SHORT.n_blocks  # after each start and each end
    lead = (clean - rung) / SENSOR_500["rate_hz"]  # [s]
    assert (lead >= 0).all() and (lead <= RUN_S + 0.5 / 80.0 + 0.009).all(), lead
    # and the mode is named, with its frequency
    result, named = _run({"mode_x": mode, "mode_y": dict(mode)}, seed=3, sensor=SENSOR_500)
    assert "structural_vibration" in named, result.headline()
    hz = next(v for v in result.model if v.name == "structural_vibration.frequency_hz")
    assert hz.value == pytest.approx(80.0, abs=max(4 * hz.u_value, 0.8))
