"""Run the project's analysis on the independent generator's recordings and tabulate.

Not a test (pytest does not collect it): the numbers behind the report of
where the pipeline and this generator agree and where they do not.

    .venv/bin/python tests/independent/survey.py clean [N_SEEDS]
    .venv/bin/python tests/independent/survey.py effects
    .venv/bin/python tests/independent/survey.py discrepancy OUT_DIR

``clean``: cases that should be clean (squareness, sensor rotation and
non-orthogonality, noise, and motion or recording choices that do not change
the measurand); for each, over seeds: the bias of ``squareness_rad`` against
the truth, its standard error, the mean stated ``u``, the scatter, and the
same for ``eps_c``. ``effects``: one recording per effect, both signs and every
spike shape, through ``analyze``. ``discrepancy``: the same recordings written
to MCAP and run through ``imu-square discrepancy --json``.
"""

import json
import math
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
from generator import generate

from imu_square.program.spec import TestProgram

PAPER = TestProgram()
FAST = TestProgram(radius_m=0.025, feed_m_per_s=0.15)
ALPHA, EPS = 100e-6, 0.0367


def _analyze(rec):
    from imu_square.pipeline.squareness import analyze

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            r = analyze(rec)
        except Exception as exc:  # a refusal is a finding
            return None, [f"{type(exc).__name__}: {exc}"]
    return r, [str(w.message) for w in caught] + list(r.quality.get("warnings", []))


def clean_cases():
    """``name -> (program, effects, sensor, motion)``: should all be clean."""
    e = {"squareness_rad": ALPHA}
    s = {"eps_c_rad": EPS}
    return {
        "paper": (PAPER, e, s, {}),
        "fast": (FAST, e, s, {}),
        "paper beta=+50u": (PAPER, e, {**s, "nonorthogonality_rad": 50e-6}, {}),
        "paper eps=-0.0367": (PAPER, e, {"eps_c_rad": -EPS}, {}),
        "paper eps=0.15": (PAPER, e, {"eps_c_rad": 0.15}, {}),
        "fast ramp 0.05 s const-jerk": (
            FAST,
            e,
            s,
            {"ramp_s": 0.05, "ramp_shape": "constant_jerk"},
        ),
        "fast ramp 0.5 s cosine": (FAST, e, s, {"ramp_s": 0.5}),
        "paper ramp 1.0 s": (PAPER, e, s, {"ramp_s": 1.0}),
        "paper start 37 deg": (TestProgram(start_angle_rad=math.radians(37)), e, s, {}),
        "paper order cw,ccw": (TestProgram(order=("cw", "ccw")), e, s, {}),
        "paper runs=2": (TestProgram(cycles_per_direction=8, runs=2), e, s, {}),
        "paper dwell 0": (TestProgram(dwell_s=0.0), e, s, {}),
        "paper centre (150,-80) mm": (TestProgram(centre_m=(0.15, -0.08)), e, s, {}),
        "paper overshoot 90 deg": (TestProgram(overshoot_rad=math.pi / 2), e, s, {}),
        "paper 500 Hz": (PAPER, e, {**s, "rate_hz": 500.0}, {}),
        "paper 4000 Hz": (PAPER, e, {**s, "rate_hz": 4000.0}, {"oversample": 1}),
        "paper clock +300 ppm": (PAPER, e, {**s, "clock_error": 300e-6}, {}),
        "paper 1/f corner 0.5 Hz": (PAPER, e, {**s, "flicker_corner_hz": 0.5}, {}),
        "paper density unstated": (PAPER, e, {**s, "state_noise_density": False}, {}),
        "paper coarse ADC 1 mg": (PAPER, e, {**s, "resolution_m_s2": 1e-3 * 9.80665}, {}),
        "paper 1% lost (gaps of 20)": (
            PAPER,
            e,
            {**s, "loss_fraction": 0.01, "mean_gap_samples": 20},
            {},
        ),
        "paper markers 50 ms late": (PAPER, e, {**s, "event_delay_s": 0.05}, {}),
        "paper static tilt 5 mrad": (PAPER, e, {**s, "tilt_x_rad": 5e-3, "tilt_y_rad": -3e-3}, {}),
        "paper gains +1%/-2%": (PAPER, e, {**s, "gain_x": 0.01, "gain_y": -0.02}, {}),
        "fast moving table": (FAST, {**e, "kinematics": "table"}, s, {}),
        "paper anti-alias 2-pole 62 Hz": (PAPER, e, {**s, "bandwidth_hz": 62.5}, {}),
        "fast anti-alias 2-pole 30 Hz": (FAST, e, {**s, "bandwidth_hz": 30.0}, {}),
        "fast 2 runs, start 90 deg": (
            TestProgram(radius_m=0.025, feed_m_per_s=0.15, runs=2, start_angle_rad=math.pi / 2),
            e,
            s,
            {},
        ),
    }


def survey_clean(n_seeds=20, names=None):
    rows = []
    for name, (prog, eff, sens, mot) in clean_cases().items():
        if names and name not in names:
            continue
        d_sq, u_sq, crb, d_eps, u_eps, notes = [], [], [], [], [], set()
        for seed in range(n_seeds):
            rec, truth = generate(
                prog, eff, sens, seed=1000 + seed, motion={"oversample": 2, **mot}
            )
            r, msgs = _analyze(rec)
            notes.update(m[:160] for m in msgs)
            if r is None:
                continue
            d_sq.append(r.squareness_rad - truth["squareness_expected_rad"])
            u_sq.append(r.u_squareness_rad)
            crb.append(r.crb_rad)
            d_eps.append(r.eps_c_rad - truth["eps_c_mean_rad"])
            u_eps.append(r.u_eps_c_rad)
        n = len(d_sq)
        row = {"case": name, "n": n, "notes": sorted(notes)}
        if n:
            d_sq, d_eps = np.array(d_sq), np.array(d_eps)
            row.update(
                bias_sq_urad=1e6 * d_sq.mean(),
                se_sq_urad=1e6 * d_sq.std(ddof=1) / math.sqrt(n) if n > 1 else math.nan,
                sd_sq_urad=1e6 * d_sq.std(ddof=1) if n > 1 else math.nan,
                u_sq_urad=1e6 * float(np.mean(u_sq)),
                crb_urad=1e6 * float(np.mean(crb)),
                max_z_sq=float(np.max(np.abs(d_sq) / np.array(u_sq))),
                bias_eps_urad=1e6 * d_eps.mean(),
                sd_eps_urad=1e6 * d_eps.std(ddof=1) if n > 1 else math.nan,
                u_eps_urad=1e6 * float(np.mean(u_eps)),
                max_z_eps=float(np.max(np.abs(d_eps) / np.array(u_eps))),
            )
        rows.append(row)
        print(json.dumps(row), flush=True)
    return rows


def effect_cases():
    """``name -> effects`` (on top of squareness ALPHA): each effect, both signs."""
    cases = {"none": {}}
    for sgn, tag in ((1, "+"), (-1, "-")):
        cases[f"servo delay mismatch {tag}"] = {
            "servo_y": {"delay_s": 0.004 * (sgn > 0)},
            "servo_x": {"delay_s": 0.004 * (sgn < 0)},
        }
        cases[f"servo lag mismatch {tag}"] = {
            "servo_x": {"tau_s": 0.01 if sgn > 0 else 0.03},
            "servo_y": {"tau_s": 0.03 if sgn > 0 else 0.01},
        }
        cases[f"lost motion x {tag}"] = {"lost_motion_x": {"lost_motion_m": sgn * 15e-6}}
        cases[f"lost motion y {tag}"] = {"lost_motion_y": {"lost_motion_m": sgn * 15e-6}}
        for shape in ("after", "centred", "led"):
            cases[f"spike x {shape} {'out' if sgn > 0 else 'in'}"] = {
                "spikes": [{"axis": "x", "shape": shape, "height_m": sgn * 8e-6, "width_s": 0.015}]
            }
            cases[f"spike y {shape} {'out' if sgn > 0 else 'in'}"] = {
                "spikes": [{"axis": "y", "shape": shape, "height_m": sgn * 8e-6, "width_s": 0.015}]
            }
        cases[f"vibration start/stop {tag}"] = {
            "mode_x": {"freq_hz": 25.0, "zeta": 0.03, "participation": sgn * 0.3},
            "mode_y": {"freq_hz": 32.0, "zeta": 0.03, "participation": sgn * 0.3},
        }
        cases[f"vibration at reversals {tag}"] = {
            "mode_x": {"freq_hz": 25.0, "zeta": 0.03, "friction_m_s2": sgn * 0.03},
            "mode_y": {"freq_hz": 32.0, "zeta": 0.03, "friction_m_s2": sgn * 0.03},
        }
        cases[f"straightness x quadratic {tag}"] = {
            "straightness_x": {"quadratic_m": sgn * 10e-6, "length_m": 0.6, "mid_m": -0.15}
        }
        cases[f"straightness y quartic {tag}"] = {
            "straightness_y": {"quartic_m": sgn * 10e-6, "length_m": 0.4, "mid_m": 0.05}
        }
        cases[f"straightness x quad + yaw {tag}"] = {
            "straightness_x": {
                "quadratic_m": sgn * 10e-6,
                "length_m": 0.6,
                "mid_m": -0.15,
                "yaw_coupled": True,
            }
        }
        cases[f"scale mismatch {tag}"] = {"scale_x": sgn * 100e-6, "scale_y": -sgn * 100e-6}
        cases[f"cyclic x {tag}"] = {"cyclic_x": {"amplitude_m": sgn * 3e-6, "pitch_m": 0.01}}
        cases[f"gravity roll/roll {tag}"] = {"tilt_gradient_rad_m": ((0.0, sgn * 5e-5), (0.0, 0.0))}
        cases[f"gravity pitch/pitch {tag}"] = {
            "tilt_gradient_rad_m": ((sgn * 5e-5, 0.0), (0.0, sgn * 5e-5))
        }
    return cases


def survey_effects(prog=PAPER, seed=7, density=None):
    """Each effect through ``analyze``; ``density`` overrides the white noise (e.g. tiny)."""
    rows = []
    sens = {"eps_c_rad": EPS}
    if density is not None:
        sens.update(noise_density_m_s2_rthz=density, resolution_m_s2=0.0)
    for name, eff in effect_cases().items():
        rec, truth = generate(
            prog,
            {"squareness_rad": ALPHA, **eff},
            sens,
            seed=seed,
            motion={"oversample": 2},
        )
        r, msgs = _analyze(rec)
        row = {
            "case": name,
            "truth_urad": 1e6 * truth["squareness_expected_rad"],
            "servo_truth_urad": 1e6 * truth["servo_mismatch_expected_rad"],
            "notes": [m[:200] for m in msgs],
        }
        if r is not None:
            row.update(
                sq_urad=1e6 * r.squareness_rad,
                u_urad=1e6 * r.u_squareness_rad,
                z=(r.squareness_rad - truth["squareness_expected_rad"]) / r.u_squareness_rad,
                servo_urad=1e6 * r.servo_mismatch_rad,
                u_servo_urad=1e6 * r.u_servo_mismatch_rad,
                eps_urad=1e6 * r.eps_c_rad,
                z_eps=(r.eps_c_rad - truth["eps_c_mean_rad"]) / r.u_eps_c_rad,
            )
        rows.append(row)
        print(json.dumps(row), flush=True)
    return rows


def survey_discrepancy(out_dir, prog=PAPER, seed=7, names=None):
    from imu_square.io.mcap import write_mcap

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    exe = Path(sys.executable).with_name("imu-square")
    for name, eff in effect_cases().items():
        if names and name not in names:
            continue
        rec, truth = generate(
            prog,
            {"squareness_rad": ALPHA, **eff},
            {"eps_c_rad": EPS},
            seed=seed,
            motion={"oversample": 2},
        )
        path = out / (name.replace(" ", "_").replace("/", "-") + ".mcap")
        write_mcap(rec, path)
        (path.with_suffix(".truth.json")).write_text(json.dumps(truth, default=str))
        proc = subprocess.run(
            [str(exe), "discrepancy", "--json", "--no-suggest", str(path)],
            capture_output=True,
            text=True,
            timeout=1800,
        )
        (path.with_suffix(".discrepancy.json")).write_text(proc.stdout)
        (path.with_suffix(".discrepancy.txt")).write_text(proc.stderr)
        lines = [ln for ln in proc.stderr.splitlines() if ln and not ln.startswith(" ")]
        row = {"case": name, "exit": proc.returncode, "headline": lines[2:4], "tail": lines[-1:]}
        try:
            doc = json.loads(proc.stdout)
            row["summary"] = _summarise_discrepancy(doc)
        except json.JSONDecodeError:
            row["stdout"] = proc.stdout[-400:]
        print(json.dumps(row), flush=True)


def _summarise_discrepancy(doc):
    """The named effects and headline of one discrepancy JSON (shape not assumed)."""
    if not isinstance(doc, dict):
        return str(doc)[:300]
    keep = {}
    for key in ("headline", "named", "effects", "named_effects", "verdict", "explained", "steps"):
        if key in doc:
            keep[key] = doc[key]
    return keep or {k: (v if not isinstance(v, list | dict) else "...") for k, v in doc.items()}


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else "clean"
    if what == "clean":
        survey_clean(int(sys.argv[2]) if len(sys.argv) > 2 else 20, sys.argv[3:] or None)
    elif what == "effects":
        quiet = [float(a.split("=")[1]) for a in sys.argv[2:] if a.startswith("density=")]
        survey_effects(FAST if "fast" in sys.argv[2:] else PAPER, density=(quiet or [None])[0])
    elif what == "discrepancy":
        survey_discrepancy(sys.argv[2], names=sys.argv[3:] or None)
