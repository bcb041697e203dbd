"""Per-file cost of the analysis, stage by stage, today's code against a baseline commit.

One recording of the paper's test (``TestProgram()``, 200 s at 1 kHz, with the
``servo_mismatch`` effect; made once into a temporary folder) is analysed from
``read_mcap`` to the ``RunResult`` of ``analyze`` with the monitor's options
(``AnalysisSettings().options()``: 4 Hz, order 1, 200 bootstrap resamples), by
two long-lived worker processes: one importing this checkout, one importing the
baseline (a detached git worktree of ``--baseline-commit`` under /tmp, or
``--baseline PATH``). The runs alternate between the two (which goes first
alternates too), so that the machine's load hits both alike. Each stage is
timed by wrapping the functions ``analyze`` calls (read, filter, segment,
cycles, fits, noise floor; "other" is the rest of ``analyze``). The table
gives the medians and the ratio new/old of the medians, wall time by stage and
the process's CPU time in total (less inflated by a loaded machine's waiting:
the nearer to a quiet core); the two results are compared too (difference of
``theta_y - theta_x`` over the Cramér-Rao bound).

``--allocator`` (default ``both``, one after the other): ``default`` runs both
sides with glibc's malloc as it comes, the code alone; ``tuned`` runs both
with the mmap and trim thresholds (32 MB, 128 MB) that the replay's worker
processes start with (``GLIBC_TUNABLES``, :data:`imu_square.monitor.replay.ALLOCATOR_TUNABLES`),
so the ratio is still the code's, and the total is what a replay worker sees.

``--trick NAME...`` measures this checkout against itself instead: one worker
with every speed trick on, and one per named trick with that trick switched off
(its library call swapped in), asked in a shuffled order each round; ``none``
switches nothing off (the spread of two identical workers), ``allocator`` runs
with glibc's defaults. ``blas`` (OpenBLAS's own thread count instead of one) is
measured apart: its threads spin on after a call and would slow the other
workers' runs.

Usage::

    python benchmarks/per_file.py [--runs 21] [--baseline PATH] [--baseline-commit 28f8832]
                                  [--allocator default|tuned|both] [--recording RUN.mcap]
    python benchmarks/per_file.py --trick none allocator blas [--recording RUN.mcap]

Writes ``benchmarks/results/per_file.json`` (or ``--output``).
"""

import argparse
import json
import os
import random
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from imu_square.monitor.replay import ALLOCATOR_TUNABLES

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
RESULTS = HERE / "results" / "per_file.json"
TRICKS = ("none", "allocator", "blas")
STAGES = ("read", "filter", "segment", "cycles", "fits", "noise", "other", "total", "total_cpu")

WORKER = r"""
import json, os, sys, time
import imu_square.pipeline.squareness as sq
from imu_square.io.mcap import read_mcap
off = os.environ.get("PER_FILE_OFF")  # --trick: the library calls a trick replaces, in its place
if off == "blas":  # OpenBLAS's own default, a thread per core: no limit while analysing
    import contextlib, imu_square.blas
    class _NoLimit:
        def limit(self, **kwargs):
            return contextlib.nullcontext()
    imu_square.blas._controller = _NoLimit
from imu_square.monitor.config import AnalysisSettings

path = sys.argv[1]
spent = {}
def timed(stage, fn):
    def wrapper(*args, **kwargs):
        t = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            spent[stage] = spent.get(stage, 0.0) + time.perf_counter() - t
    return wrapper
for name, stage in (("filter_recording", "filter"), ("segment", "segment"),
                    ("cycle_traces", "cycles"), ("fit_mean_traces", "fits"),
                    ("fit_cycles", "fits"), ("fit_cross_terms", "fits"),
                    ("noise_floor", "noise")):
    setattr(sq, name, timed(stage, getattr(sq, name)))
options = AnalysisSettings().options()
for line in sys.stdin:
    spent.clear()
    c0, t0 = time.process_time(), time.perf_counter()
    rec = read_mcap(path)
    t1 = time.perf_counter()
    res = sq.analyze(rec, options)
    t2, c2 = time.perf_counter(), time.process_time()
    spent["total_cpu"] = c2 - c0
    spent["read"] = t1 - t0
    spent["other"] = (t2 - t1) - sum(v for k, v in spent.items() if k not in ("read", "total_cpu"))
    spent["total"] = t2 - t0
    out = {"times": spent, "squareness_rad": res.squareness_rad, "crb_rad": res.crb_rad,
           "eps_c_rad": res.eps_c_rad, "u_squareness_rad": res.u_squareness_rad,
           "u_bootstrap_rad": res.u_squareness_bootstrap_rad, "period_s": res.period_s}
    print(json.dumps(out), flush=True)
"""


def make_recording(path, seed):
    """The paper's test with a servo mismatch, 200 s at 1 kHz, written as MCAP."""
    from imu_square.io.mcap import write_mcap
    from imu_square.program import TestProgram
    from imu_square.simulate import simulate_run, with_effects

    rec, _ = simulate_run(TestProgram(), *with_effects(["servo_mismatch"]), seed=seed)
    write_mcap(rec, path)
    return rec.duration_s, rec.n_samples


def baseline_tree(commit):
    """A detached worktree of ``commit`` under /tmp, made once."""
    path = Path(tempfile.gettempdir()) / f"per_file_old_{commit}"
    if not path.exists():
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "--detach", str(path), commit],
            check=True,
            capture_output=True,
        )
    return path


def start_worker(code_root, mcap, allocator, off=None):
    env = dict(os.environ, PYTHONPATH=str(code_root), OPENBLAS_NUM_THREADS="1")
    env.pop("GLIBC_TUNABLES", None)
    if allocator == "tuned" and off != "allocator":  # read by glibc when the worker starts
        env["GLIBC_TUNABLES"] = ALLOCATOR_TUNABLES
    env.setdefault("OMP_NUM_THREADS", "1")
    if off == "blas":  # OpenBLAS's own default: a thread per core (and no limit: the worker)
        for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            env.pop(var, None)
        env["PER_FILE_OFF"] = off
    return subprocess.Popen(
        [sys.executable, "-c", WORKER, str(mcap)],
        cwd=str(code_root),
        env=env,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )


def ask(worker):
    worker.stdin.write("run\n")
    worker.stdin.flush()
    line = worker.stdout.readline()
    if not line:
        raise RuntimeError("a worker died; run it by hand to see why")
    return json.loads(line)


ALLOCATOR_NOTE = {
    "default": "glibc's defaults: the code alone",
    "tuned": "glibc's mmap/trim thresholds raised as in the replay's worker processes",
}


def measure(old_root, mcap, allocator, args):
    """Interleaved runs of both sides under one allocator setting; medians and differences."""
    load_before = os.getloadavg()
    workers = {
        "old": start_worker(old_root, mcap, allocator),
        "new": start_worker(ROOT, mcap, allocator),
    }
    try:
        for _ in range(args.warmup):
            for w in workers.values():
                ask(w)
        runs = {"old": [], "new": []}
        for i in range(args.runs):
            order = ("old", "new") if i % 2 == 0 else ("new", "old")
            for side in order:
                runs[side].append(ask(workers[side]))
    finally:
        for w in workers.values():
            w.stdin.close()
            w.wait(timeout=30)
    medians = {
        side: {s: statistics.median(r["times"].get(s, 0.0) for r in runs[side]) for s in STAGES}
        for side in runs
    }
    ratio_runs = [
        b["times"]["total"] / a["times"]["total"]
        for a, b in zip(runs["old"], runs["new"], strict=True)
    ]
    old, new = runs["old"][-1], runs["new"][-1]
    return {
        "load_before": load_before,
        "load_after": os.getloadavg(),
        "median_s": medians,
        "ratio_new_over_old": {
            s: medians["new"][s] / medians["old"][s] if medians["old"][s] else None for s in STAGES
        },
        "ratio_total_median_of_pairs": statistics.median(ratio_runs),
        "difference": {
            "squareness_over_crb": (new["squareness_rad"] - old["squareness_rad"]) / old["crb_rad"],
            "eps_c_rad": new["eps_c_rad"] - old["eps_c_rad"],
            "u_squareness_rel": new["u_squareness_rad"] / old["u_squareness_rad"] - 1,
            "u_bootstrap_rel": new["u_bootstrap_rad"] / old["u_bootstrap_rad"] - 1,
            "period_rel": new["period_s"] / old["period_s"] - 1,
            "crb_rel": new["crb_rad"] / old["crb_rad"] - 1,
        },
    }


def measure_tricks(mcap, tricks, args):
    """This checkout with every trick on, and with each trick off in turn, interleaved.

    One worker per setting, all under the tuned allocator (as ``analyze`` runs) but
    the allocator's own row; each round asks every worker once, in a shuffled order
    (a fixed rotation would always run the same worker after the same other, and
    OpenBLAS's threads spin on after a call: they slow whichever run comes next).
    ``none`` switches nothing off: the spread between two identical workers.
    Returns each trick's medians and the milliseconds it saves of the per-file time.
    """
    rng = random.Random(args.seed)
    load_before = os.getloadavg()
    workers = {"on": start_worker(ROOT, mcap, "tuned")}
    workers.update({t: start_worker(ROOT, mcap, "tuned", off=t) for t in tricks})
    names = list(workers)
    runs = {name: [] for name in names}
    try:
        for _ in range(args.warmup):
            for w in workers.values():
                ask(w)
        for _ in range(args.runs):
            for name in rng.sample(names, len(names)):
                runs[name].append(ask(workers[name]))
    finally:
        for w in workers.values():
            w.stdin.close()
            w.wait(timeout=30)
    medians = {
        name: {s: statistics.median(r["times"].get(s, 0.0) for r in runs[name]) for s in STAGES}
        for name in names
    }
    on = runs["on"]
    result = {"load_before": load_before, "load_after": os.getloadavg(), "median_s": medians}
    result["tricks"] = {}
    for t in tricks:
        pairs = zip(on, runs[t], strict=True)
        saved = [b["times"]["total"] - a["times"]["total"] for a, b in pairs]
        result["tricks"][t] = {
            "saved_ms_median_of_pairs": 1e3 * statistics.median(saved),
            "saved_ms_of_medians": 1e3 * (medians[t]["total"] - medians["on"]["total"]),
            "share_of_per_file_time": statistics.median(saved) / medians["on"]["total"],
            "squareness_over_crb": (runs[t][-1]["squareness_rad"] - on[-1]["squareness_rad"])
            / on[-1]["crb_rad"],
            "u_squareness_rel": runs[t][-1]["u_squareness_rad"] / on[-1]["u_squareness_rad"] - 1,
        }
    return result


def print_tricks(r, args):
    """The tricks' table: per-file time with all on, each one's saving and share."""
    on = 1e3 * r["median_s"]["on"]["total"]
    print(
        f"\n{args.runs} interleaved rounds, load {r['load_before'][0]:.2f} -> "
        f"{r['load_after'][0]:.2f} (1-min average, 2 cores); all tricks on: {on:.1f} ms a file"
    )
    print(f"{'trick':12s} {'off [ms]':>9s} {'saved [ms]':>11s} {'share':>7s} {'d sq/CRB':>9s}")
    for t, v in r["tricks"].items():
        off = 1e3 * r["median_s"][t]["total"]
        print(
            f"{t:12s} {off:9.1f} {v['saved_ms_median_of_pairs']:11.1f} "
            f"{100 * v['share_of_per_file_time']:6.1f}% {v['squareness_over_crb']:9.1e}"
        )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=21, help="timed runs per side (>= 15)")
    parser.add_argument("--warmup", type=int, default=3)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--baseline", help="source tree of the old code (default: a worktree)")
    parser.add_argument("--baseline-commit", default="28f8832")
    parser.add_argument(
        "--allocator",
        choices=("default", "tuned", "both"),
        default="both",
        help="glibc's defaults (the code alone), the thresholds the replay's worker processes "
        "start with, or both in turn (default); each on both sides",
    )
    parser.add_argument(
        "--recording",
        metavar="RUN.mcap",
        help="time this recording instead of the paper's test with a servo mismatch (e.g. one "
        "of benchmarks/replay.py's: a typical machine, whose spikes cost the robust fits more)",
    )
    parser.add_argument(
        "--trick",
        nargs="+",
        choices=TRICKS,
        help="instead of a baseline: this checkout with each named speed trick switched off "
        "in turn (its library call swapped in), against all on, interleaved",
    )
    parser.add_argument("--output", default=str(RESULTS), help="the JSON file to write")
    args = parser.parse_args(argv)
    if args.trick:
        return main_tricks(args)
    old_root = Path(args.baseline) if args.baseline else baseline_tree(args.baseline_commit)
    modes = ("default", "tuned") if args.allocator == "both" else (args.allocator,)
    result = {"baseline": str(old_root), "runs": args.runs, "allocators": {}}
    with tempfile.TemporaryDirectory(prefix="imu-per-file-") as tmp:
        if args.recording:
            from imu_square.io.mcap import read_mcap

            mcap = Path(args.recording).resolve()  # the workers run in their own trees
            rec = read_mcap(mcap)
            duration, n = rec.duration_s, rec.n_samples
        else:
            mcap = Path(tmp) / "run.mcap"
            duration, n = make_recording(mcap, args.seed)
        size_mb = mcap.stat().st_size / 1e6
        result["recording"] = {"duration_s": duration, "samples": n, "mb": size_mb}
        result["recording"]["source"] = str(args.recording or f"seed {args.seed}")
        for mode in modes:
            result["allocators"][mode] = measure(old_root, mcap, mode, args)
    for mode in modes:
        r = result["allocators"][mode]
        load_before, load_after = r["load_before"], r["load_after"]
        print(
            f"\nallocator {mode} ({ALLOCATOR_NOTE[mode]}), both sides alike: "
            f"{duration:.0f} s at {n / duration:.0f} Hz, {args.runs} interleaved runs per side, "
            f"load {load_before[0]:.2f} -> {load_after[0]:.2f} (1-min average, 2 cores)"
        )
        medians = r["median_s"]
        print(f"{'stage':10s} {'old [ms]':>10s} {'new [ms]':>10s} {'new/old':>8s}")
        for s in STAGES:
            o, w = 1e3 * medians["old"][s], 1e3 * medians["new"][s]
            print(f"{s:10s} {o:10.1f} {w:10.1f} {w / o if o else float('nan'):8.2f}")
        print(f"median over pairs of total new/old: {r['ratio_total_median_of_pairs']:.2f}")
        d = r["difference"]
        print(
            f"results: squareness differs by {d['squareness_over_crb']:.1e} CRB, eps_c by "
            f"{d['eps_c_rad']:.1e} rad, u by {d['u_squareness_rel']:.1e} (relative), "
            f"CRB by {d['crb_rel']:.1e} (relative)"
        )
    if len(modes) == 2:
        code = result["allocators"]["default"]["median_s"]
        tuned = result["allocators"]["tuned"]["median_s"]
        print(
            f"\ntotal [ms]: old {1e3 * code['old']['total']:.1f} -> new "
            f"{1e3 * code['new']['total']:.1f} (code alone), new with the tuned allocator "
            f"{1e3 * tuned['new']['total']:.1f} (old with it {1e3 * tuned['old']['total']:.1f})"
        )
    write(result, args.output)


def main_tricks(args):
    with tempfile.TemporaryDirectory(prefix="imu-per-file-") as tmp:
        mcap, source = _recording(args, tmp)
        result = {"recording": source, "runs": args.runs, "groups": []}
        # The BLAS threads' spinning would slow the other workers' runs: measured apart.
        groups = [[t for t in args.trick if t != "blas"], [t for t in args.trick if t == "blas"]]
        for group in filter(None, groups):
            result["groups"].append(measure_tricks(mcap, group, args))
    for group in result["groups"]:
        print_tricks(group, args)
    write(result, args.output)


def _recording(args, tmp):
    if args.recording:
        return Path(args.recording).resolve(), str(args.recording)
    mcap = Path(tmp) / "run.mcap"
    make_recording(mcap, args.seed)
    return mcap, f"the paper's test with a servo mismatch, seed {args.seed}"


def write(result, output):
    path = Path(output)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(result, indent=1))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
