"""The designed alarms on simulated years of nights: false alarms and detection delays.

Full simulation of thousands of machine-years is too slow, so:

1. A pool of real nights per program: the simulator (the typical machine,
   ``machine_typical.toml``; the paper's sensor, ``sensor_paper.toml``) and the
   pipeline (``analyze``) run on ``--pool`` seeds of two programs: the paper's
   test (``program_paper.toml``: r = 100 mm at 6000 mm/min, 0.1 m/s^2) and a
   faster one (r = 50 mm at 12 000 mm/min, 0.8 m/s^2, 15 cycles each way),
   whose night scatters far less.
2. The pool's ``z = (S - expected) / u`` is checked against the law the design
   assumes (Student's t with the runs' degrees of freedom): bias, scatter over
   the median ``u``, coverage of 1, 2, 3 ``u``, and a Kolmogorov-Smirnov test.
3. Per program, the alarms are designed for one false alarm in 730 nights,
   with the pool's median ``u`` as sigma, the runs' degrees of freedom and a
   baseline of ``--baseline-runs`` nights (``baseline_sd_ratio = 1/sqrt(N)``).
4. Machines are drawn from the pool (bootstrap): each gets a baseline, the
   mean of N pool nights, and its nights are further pool nights (never its
   own baseline's), with a change added: none (a clean year), a 10 µm/m step
   (from the first night, and after 100 quiet nights), and a 10 µm/m ramp
   over 90 nights. The charts run on them exactly as the monitor runs them.
   A pool of a few hundred nights cannot resolve the Shewhart's far tail
   (one pool night past its limit alarms every few hundred nights), so the
   clean year is also run on nights made of 15 cycle pairs drawn from all
   the pool's pairs: real per-cycle scatter, a continuum of ``z``.
5. The baseline's effect for N = 3, 5, 10, 20 (Student's t model, fast
   program): false alarms a year of the design that ignores the baseline's
   error (A), of the same limits with ``Delta / sqrt(u^2 + u_baseline^2)``
   (B), and of the design that allows for it (C), with C's detection delays.

Prints the tables and writes ``benchmarks/results/monitor.json``.

Usage::

    python benchmarks/monitor.py [--quick] [--pool 200] [--workers 2] [--baseline-runs 10]

``--quick``: 40 nights per pool, fewer machines, N = 3 and 20 only.
"""

import os

# The ARL integral equations solve 50-400 unknowns: OpenBLAS threads only cost
# there, and on a busy machine they cost 40 times. Set before numpy loads.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import math
import multiprocessing
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy import stats

from imu_square.errors import AnalysisError
from imu_square.json_values import json_safe
from imu_square.monitor.stats.alarms import (
    NIGHTS_PER_YEAR,
    design_alarms,
    to_design_law,
)
from imu_square.monitor.stats.arl import Cusum, Ewma, NightLaw, Shewhart, baseline_average
from imu_square.monitor.stats.charts import (
    CHARTS,
    ChartLimits,
    NightSampler,
    alarm_counts,
    first_alarms,
)
from imu_square.program import read_program
from imu_square.simulate import data_path, read_machine, read_sensor, simulate_run
from imu_square.units import MM, MM_PER_MIN, URAD

RESULTS = Path(__file__).parent / "results" / "monitor.json"
ARL0 = 730.0  # one false alarm in two years of nights
STEP = 10 * URAD
RAMP_NIGHTS = 90
QUIET = 100  # nights before the step in the steady-state scenario
HORIZON = 5 * 365  # nights followed after the change


def _programs():
    paper = read_program(data_path("program_paper.toml"))
    fast = replace(paper, radius_m=50 * MM, feed_m_per_s=12_000 * MM_PER_MIN)
    return {"paper": paper, "fast": fast}


def _night(task):
    """Simulate and analyse one night; (S, u, dof, expected) or the refusal."""
    from imu_square.pipeline.squareness import analyze

    name, seed = task
    program = _programs()[name]
    machine = read_machine(data_path("machine_typical.toml"))
    sensor = read_sensor(data_path("sensor_paper.toml"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        recording, truth = simulate_run(program, machine, sensor, seed=seed)
        try:
            r = analyze(recording)
        except AnalysisError as exc:
            return {"seed": seed, "refused": str(exc)}
    return {
        "seed": seed,
        "squareness_rad": r.squareness_rad,
        "u_rad": r.u_squareness_rad,
        "dof": int(r.u_squareness_dof),
        "expected_rad": truth["expected_squareness_rad"],
        "pairs_rad": np.asarray(r.per_cycle["squareness_rad"]) - truth["expected_squareness_rad"],
    }


def _pool(name, n, workers):
    start = time.perf_counter()
    tasks = [(name, 100_000 * (name == "fast") + seed) for seed in range(n)]
    if workers > 1:
        with multiprocessing.Pool(workers) as pool:
            rows = pool.map(_night, tasks, chunksize=4)
    else:
        rows = [_night(t) for t in tasks]
    ok = [r for r in rows if "refused" not in r]
    return {
        "s": np.array([r["squareness_rad"] for r in ok]),
        "u": np.array([r["u_rad"] for r in ok]),
        "dof": np.array([r["dof"] for r in ok], dtype=float),
        "expected": np.array([r["expected_rad"] for r in ok]),
        "pairs": [r["pairs_rad"] for r in ok],
        "refused": [r for r in rows if "refused" in r],
        "wall_s": time.perf_counter() - start,
    }


def _pool_check(pool):
    """The pool's z against Student's t with the runs' degrees of freedom."""
    err = pool["s"] - pool["expected"]
    z = err / pool["u"]
    nu = float(np.median(pool["dof"]))
    n = z.size
    coverage = {}
    for k in (1, 2, 3):
        observed = float(np.mean(np.abs(z) <= k))
        coverage[f"{k}u"] = {
            "observed": observed,
            "se": math.sqrt(observed * (1 - observed) / n),
            "t_model": float(1 - 2 * stats.t.sf(k, nu)),
            "normal": float(1 - 2 * stats.norm.sf(k)),
        }
    return {
        "n_nights": n,
        "refused": len(pool["refused"]),
        "nu": nu,
        "median_u_urad": float(np.median(pool["u"]) / URAD),
        "bias_urad": float(err.mean() / URAD),
        "u_bias_urad": float(err.std(ddof=1) / math.sqrt(n) / URAD),
        "scatter_over_median_u": float(pool["s"].std(ddof=1) / np.median(pool["u"])),
        "mean_z2": float(np.mean(z**2)),
        "u_mean_z2": float(np.std(z**2, ddof=1) / math.sqrt(n)),
        "t_model_mean_z2": nu / (nu - 2),
        "ks_pvalue_t": float(stats.kstest(z, "t", args=(nu,)).pvalue),
        "ks_pvalue_normal": float(stats.kstest(z, "norm").pvalue),
        "coverage": coverage,
    }


class NightBootstrap:
    """Machines drawn from a pool of real nights: a baseline of N nights, then other nights.

    ``draw`` follows :class:`imu_square.monitor.stats.charts.NightSampler`: the
    change ``mean`` (in rad, night by night, the last value held) is added
    to each night's squareness. A pool of a few hundred nights resolves the
    charts that average (EWMA, CUSUM) but not the Shewhart's far tail: one
    pool night beyond its limit alarms every few hundred nights.
    """

    def __init__(self, pool, n_paths, baseline_runs, design_nu, mean, rng):
        self.s, self.u, self.dof = pool["s"], pool["u"], pool["dof"]
        self.order = np.argsort(rng.random((n_paths, self.s.size)), axis=1)
        self.baseline = self.s[self.order[:, :baseline_runs]].mean(axis=1)
        self.baseline_runs = baseline_runs
        self.design_nu = design_nu
        self.mean = np.atleast_1d(np.asarray(mean, dtype=np.float64))

    def draw(self, rng, paths, first, n):
        pick = rng.integers(self.baseline_runs, self.s.size, size=(paths.size, n))
        idx = np.take_along_axis(self.order[paths], pick, axis=1)
        change = self.mean[np.minimum(np.arange(first, first + n), self.mean.size - 1)]
        z = (self.s[idx] + change - self.baseline[paths][:, None]) / self.u[idx]
        return to_design_law(z, self.dof[idx], self.design_nu)


class PairBootstrap:
    """New nights from the pool's cycle pairs: each the mean of 15 pairs drawn from all nights.

    Its ``S`` and ``u`` are the mean and type A uncertainty of the drawn
    pairs, so the real per-cycle scatter, with whatever tails it has, gives
    nights with a continuum of ``z`` (the simulated nights have no
    night-to-night component beyond their cycles' noise, which the pool's
    scatter over its median ``u`` confirms). The baseline is the mean of N
    such nights.
    """

    def __init__(self, pool, n_paths, baseline_runs, mean, rng):
        self.pairs = np.concatenate(pool["pairs"])
        self.m = int(np.median([len(p) for p in pool["pairs"]]))
        draw = rng.integers(0, self.pairs.size, size=(n_paths, baseline_runs * self.m))
        self.baseline = self.pairs[draw].mean(axis=1)
        self.mean = np.atleast_1d(np.asarray(mean, dtype=np.float64))

    def draw(self, rng, paths, first, n):
        v = self.pairs[rng.integers(0, self.pairs.size, size=(paths.size, n, self.m))]
        u = v.std(axis=2, ddof=1) / math.sqrt(self.m)
        change = self.mean[np.minimum(np.arange(first, first + n), self.mean.size - 1)]
        return (v.mean(axis=2) + change - self.baseline[paths][:, None]) / u


def _summary(rl):
    """Median, 90th percentile, mean and its SE of run lengths; censored counted as inf."""
    kept = rl[~np.isnan(rl)]
    censored = float(np.mean(~np.isfinite(kept)))
    srt = np.sort(kept)

    def q(p):
        v = srt[min(srt.size - 1, math.ceil(p * srt.size) - 1)]
        return None if not np.isfinite(v) else float(v)

    finite = kept[np.isfinite(kept)]
    mean = float(finite.mean()) if censored == 0 else None
    se = float(finite.std(ddof=1) / math.sqrt(finite.size)) if censored == 0 else None
    return {"median": q(0.5), "p90": q(0.9), "mean": mean, "se": se, "censored": censored}


def _clean(design, sampler, machines, rng):
    """One in-control year on each machine: the scheme, and each chart alone."""
    counts = alarm_counts(design.limits, design.warnings, sampler, machines, 365, rng, block=64)
    per = counts["alarms"] / 365 * NIGHTS_PER_YEAR
    out = {
        "machines": machines,
        "false_alarms_per_year": float(per.mean()),
        "se": float(per.std(ddof=1) / math.sqrt(machines)),
        "by_chart_per_year": {
            c: float(counts["by_chart"][c].mean() / 365 * NIGHTS_PER_YEAR) for c in CHARTS
        },
        "warning_fraction": float(counts["warning_nights"].sum() / (machines * 365)),
        "warning_episodes_per_year": float(counts["warning_onsets"].mean() / 365 * NIGHTS_PER_YEAR),
        "alone": {},
    }
    for name in CHARTS:
        c = alarm_counts(_only(design.limits, name), None, sampler, machines, 365, rng, block=64)
        rate = c["alarms"] / 365
        r, se = rate.mean(), rate.std(ddof=1) / math.sqrt(machines)
        out["alone"][name] = {
            "alarms": int(c["alarms"].sum()),
            "mc_arl0": float(1 / r) if r > 0 else math.inf,
            "mc_se": float(se / r**2) if r > 0 else math.inf,
            "computed_arl0": getattr(design, name).arl0,
        }
    return out


def _years(design, pool, args, rng):
    """Clean years, a step and a ramp on machines drawn from the pool."""
    nu, machines, runs = design.nu, args.machines, args.baseline_runs
    nights = NightBootstrap(pool, machines, runs, nu, 0.0, rng)
    out = {
        "design_false_alarms_per_year": NIGHTS_PER_YEAR / design.check.arl0,
        "design_se": NIGHTS_PER_YEAR * design.check.u_arl0 / design.check.arl0**2,
        "clean_nights": _clean(design, nights, machines, rng),
        "clean_pairs": _clean(design, PairBootstrap(pool, machines, runs, 0.0, rng), machines, rng),
    }
    scenarios = {
        "step": (STEP, 0),
        "step_after_quiet": (np.concatenate([np.zeros(QUIET), [STEP]]), QUIET),
        "ramp": (STEP * np.minimum(np.arange(1, RAMP_NIGHTS + 1) / RAMP_NIGHTS, 1.0), 0),
    }
    for name, (mean, burn_in) in scenarios.items():
        s = NightBootstrap(pool, machines, runs, nu, mean, rng)
        rl = first_alarms(design.limits, s, machines, HORIZON, rng, burn_in=burn_in)
        out[name] = {c: _summary(rl[c]) for c in (*CHARTS, "combined")}
    out["step"]["computed_arl1_mean"] = {c: getattr(design, c).arl1_mean for c in CHARTS}
    return out


def _only(limits, name):
    return ChartLimits(
        limits.shewhart if name == "shewhart" else math.inf,
        limits.ewma_lambda,
        limits.ewma if name == "ewma" else math.inf,
        limits.cusum_k,
        limits.cusum if name == "cusum" else math.inf,
    )


class RescaledSampler:
    """Option B: ``z = Delta / sqrt(u^2 + u_baseline^2)``, the baseline's error per machine.

    Student's t model: ``z = (Z + o_p) / sqrt(W / nu + ratio^2)`` with
    ``o_p = -e_p / sigma`` and ``ratio = u_baseline / sigma``.
    """

    def __init__(self, nu, offsets, ratio):
        self.nu, self.offsets, self.ratio = nu, offsets, ratio

    def draw(self, rng, paths, first, n):
        z = rng.standard_normal((paths.size, n)) + self.offsets[paths][:, None]
        return z / np.sqrt(rng.chisquare(self.nu, size=z.shape) / self.nu + self.ratio**2)


def baseline_effect(design, baseline_sd_ratios):
    """What a baseline's error does to a design's in-control run lengths.

    Parameters
    ----------
    design : AlarmDesign
        A design (its limits are kept as they are).
    baseline_sd_ratios : sequence of float
        Baseline standard errors over the night's sigma (``1/sqrt(N)`` for N runs). [1]

    Returns
    -------
    list of dict
        Per ratio and chart: ``rate_arl`` (one over the false-alarm rate
        averaged over baselines), ``mean_arl`` (``E[ARL0]``) and ``p10_arl``
        (one baseline in ten does worse). [nights]
    """
    law = NightLaw(design.nu)
    charts = {
        "shewhart": Shewhart(design.shewhart.limit),
        "ewma": Ewma(design.ewma.parameter, design.ewma.limit),
        "cusum": Cusum(design.cusum.parameter, design.cusum.limit),
    }
    out = []
    for rho in baseline_sd_ratios:
        row = {"baseline_sd_ratio": float(rho)}
        for name, chart in charts.items():
            row[name] = baseline_average(chart, law, float(rho))
        out.append(row)
    return out


def _baseline_table(pool_check, sigma, runs, args, rng):
    """False alarms a year with a baseline of N runs: ignored (A), rescaled (B), designed (C)."""
    nu = pool_check["nu"]
    exact = design_alarms(ARL0, sigma, nu=nu, mc_nights=args.mc_nights, seed=1)
    effect = baseline_effect(exact, [1 / math.sqrt(n) for n in runs])
    rows = []
    machines = args.machines
    for n, eff in zip(runs, effect, strict=True):
        rho = 1 / math.sqrt(n)
        offsets = rho * rng.standard_normal(machines)
        span = int(3 * ARL0)
        a = alarm_counts(exact.limits, None, NightSampler(nu, 0.0, offsets), machines, span, rng)
        b = alarm_counts(exact.limits, None, RescaledSampler(nu, offsets, rho), machines, span, rng)
        designed = design_alarms(
            ARL0, sigma, nu=nu, baseline_sd_ratio=rho, mc_nights=args.mc_nights, seed=2
        )
        rows.append(
            {
                "baseline_runs": n,
                "baseline_sd_ratio": rho,
                "A_ignored": _per_year(a, span),
                "A_computed_rate_arl": {c: eff[c]["rate_arl"] for c in CHARTS},
                "A_computed_mean_arl": {c: _finite(eff[c]["mean_arl"]) for c in CHARTS},
                "A_computed_p10_arl": {c: eff[c]["p10_arl"] for c in CHARTS},
                "B_rescaled": _per_year(b, span),
                "C_designed": {
                    "false_alarms_per_year": NIGHTS_PER_YEAR / designed.check.arl0,
                    "se": NIGHTS_PER_YEAR * designed.check.u_arl0 / designed.check.arl0**2,
                    "limits": {c: getattr(designed, c).limit for c in CHARTS},
                    "cusum_k": designed.cusum.parameter,
                    "step_arl1": _finite(designed.check.arl1),
                    "step_median": _finite(designed.check.step_median),
                    "step_p90": _finite(designed.check.step_p90),
                    "step_arl1_steady": _finite(designed.check.arl1_steady),
                    "ramp_median": _finite(designed.check.ramp_median),
                    "ramp_p90": _finite(designed.check.ramp_p90),
                },
            }
        )
    return {
        "exact_design": exact.to_json_dict(),
        "exact_step_arl1": _finite(exact.check.arl1),
        "exact_step_median": _finite(exact.check.step_median),
        "exact_ramp_median": _finite(exact.check.ramp_median),
        "rows": rows,
    }


def _per_year(counts, span):
    per = counts["alarms"] / span * NIGHTS_PER_YEAR
    se = per.std(ddof=1) / math.sqrt(per.size)
    return {"false_alarms_per_year": float(per.mean()), "se": float(se)}


def _finite(v):
    return None if v is None or not math.isfinite(v) else float(v)


def _fmt(v, digits=0):
    return "-" if v is None or not math.isfinite(v) else f"{v:.{digits}f}"


def _print_program(name, prog):
    p = print
    c = prog["pool"]
    p(
        f"\n== {name} program: {c['n_nights']} nights ({c['refused']} refused), "
        f"median u {c['median_u_urad']:.1f} µm/m, nu {c['nu']:g}, pool {prog['pool_wall_s']:.0f} s"
    )
    p(
        f"  bias {c['bias_urad']:+.1f} ± {c['u_bias_urad']:.1f} µm/m; scatter/median u "
        f"{c['scatter_over_median_u']:.2f}; mean z^2 {c['mean_z2']:.2f} ± {c['u_mean_z2']:.2f} "
        f"(t {c['t_model_mean_z2']:.2f}); KS p: t {c['ks_pvalue_t']:.2f}, "
        f"normal {c['ks_pvalue_normal']:.2f}"
    )
    p("  coverage  observed     t model  normal")
    for k, v in c["coverage"].items():
        p(f"  {k:>8}  {v['observed']:.3f}±{v['se']:.3f}  {v['t_model']:.3f}   {v['normal']:.3f}")
    d = prog["design"]
    p(
        f"  design ({prog['design_wall_s']:.0f} s): sigma {d['sigma_urad']:.1f} µm/m, step "
        f"{d['step_sd']:.2f} sigma, baseline {d['baseline_sd_ratio']:.2f} sigma; limits: "
        f"Shewhart {d['shewhart']['limit']:.2f}, EWMA {d['ewma']['limit']:.3f} (lambda "
        f"{d['ewma']['parameter']}), CUSUM {d['cusum']['limit']:.2f} (k "
        f"{d['cusum']['parameter']:.3f}); overlap {d['overlap']:.2f}"
    )
    y = prog["years"]
    p(
        f"  false alarms a year: design {y['design_false_alarms_per_year']:.3f} "
        f"± {y['design_se']:.3f}"
    )
    for label, key in (("real nights", "clean_nights"), ("nights of real pairs", "clean_pairs")):
        cy = y[key]
        p(
            f"  clean years, {label} ({cy['machines']} machines): "
            f"{cy['false_alarms_per_year']:.3f} ± {cy['se']:.3f} a year; warning "
            f"{100 * cy['warning_fraction']:.1f} % of nights, "
            f"{cy['warning_episodes_per_year']:.1f} episodes a year"
        )
    p("  ARL0 alone   computed  MC real nights  MC nights of pairs [nights]")
    for ch in CHARTS:
        row = []
        for key in ("clean_nights", "clean_pairs"):
            v = y[key]["alone"][ch]
            row.append("no alarm" if v["alarms"] == 0 else f"{v['mc_arl0']:.0f} ± {v['mc_se']:.0f}")
        computed = y["clean_nights"]["alone"][ch]["computed_arl0"]
        p(f"  {ch:>10}  {computed:8.0f}  {row[0]:>14}  {row[1]:>14}")
    p(
        f"  delay [nights]  step: median p90 found  mean (computed) | after {QUIET} quiet: "
        f"median p90 | ramp: median p90 found"
    )
    for ch in (*CHARTS, "combined"):
        s, q, r = y["step"][ch], y["step_after_quiet"][ch], y["ramp"][ch]
        comp = y["step"]["computed_arl1_mean"].get(ch)
        mean = "-" if s["mean"] is None else f"{s['mean']:.1f}±{s['se']:.1f}"
        p(
            f"  {ch:>10}  {_fmt(s['median']):>6} {_fmt(s['p90']):>5} "
            f"{100 * (1 - s['censored']):4.0f}%  {mean:>11} ({_fmt(comp, 1)}) | "
            f"{_fmt(q['median']):>6} {_fmt(q['p90']):>5} | {_fmt(r['median']):>6} "
            f"{_fmt(r['p90']):>5} {100 * (1 - r['censored']):4.0f}%"
        )


def _print(results):
    for name, prog in results["programs"].items():
        _print_program(name, prog)
    b = results["baseline"]
    print(
        f"\n== baseline of N runs (Student's t model, fast program; the exact-baseline "
        f"design finds the step in a median {_fmt(b['exact_step_median'])} nights)"
    )
    print(
        "   N  false alarms a year: A ignored  B rescaled    C designed  | C: k  "
        "step median p90  ramp median p90"
    )
    for r in b["rows"]:
        a, bb, c = r["A_ignored"], r["B_rescaled"], r["C_designed"]
        print(
            f"  {r['baseline_runs']:2d}  {a['false_alarms_per_year']:18.2f} ± {a['se']:.2f}  "
            f"{bb['false_alarms_per_year']:5.2f} ± {bb['se']:.2f}  "
            f"{c['false_alarms_per_year']:6.2f} ± {c['se']:.2f} | {c['cusum_k']:.2f}  "
            f"{_fmt(c['step_median']):>6} {_fmt(c['step_p90']):>5}  "
            f"{_fmt(c['ramp_median']):>6} {_fmt(c['ramp_p90']):>5}"
        )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--pool", type=int, default=None, help="nights per pool (default 200)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--baseline-runs", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    args.pool = args.pool or (40 if args.quick else 200)
    args.machines = 500 if args.quick else 4000
    args.mc_nights = 400_000 if args.quick else 4_000_000
    runs = (3, 20) if args.quick else (3, 5, 10, 20)
    rng = np.random.default_rng(args.seed)
    start = time.perf_counter()
    results = {
        "arl0_nights": ARL0,
        "step_urad": STEP / URAD,
        "ramp_nights": RAMP_NIGHTS,
        "baseline_runs": args.baseline_runs,
        "quick": args.quick,
        "programs": {},
    }
    for name in _programs():
        pool = _pool(name, args.pool, args.workers)
        check = _pool_check(pool)
        t0 = time.perf_counter()
        design = design_alarms(
            ARL0,
            float(np.median(pool["u"])),
            nu=check["nu"],
            baseline_sd_ratio=1 / math.sqrt(args.baseline_runs),
            mc_nights=args.mc_nights,
            seed=args.seed,
        )
        results["programs"][name] = {
            "pool": check,
            "pool_nights_urad": {k: (pool[k] / URAD).tolist() for k in ("s", "u", "expected")},
            "pool_wall_s": pool["wall_s"],
            "design": design.to_json_dict(),
            "design_text": design.describe(),
            "design_wall_s": time.perf_counter() - t0,
            "years": _years(design, pool, args, rng),
        }
    fast = results["programs"]["fast"]
    results["baseline"] = _baseline_table(
        fast["pool"], fast["design"]["sigma_urad"] * URAD, runs, args, rng
    )
    results["wall_s"] = time.perf_counter() - start
    _print(results)
    for name, prog in results["programs"].items():
        print(f"\n{name}: {prog['design_text']}")
    print(f"\ntotal {results['wall_s']:.0f} s")
    RESULTS.parent.mkdir(exist_ok=True)
    RESULTS.write_text(json.dumps(json_safe(results), indent=1, allow_nan=False))
    print(f"wrote {RESULTS}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
