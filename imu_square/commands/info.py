"""``imu-square info``: what an MCAP recording holds."""

import json

from imu_square.cli import EXIT_INCOMPLETE
from imu_square.io.mcap import scan_mcap, summarize
from imu_square.units import UG

HELP = "summarise an MCAP recording"


def register(sub):
    """Add the ``info`` subcommand."""
    p = sub.add_parser(
        "info",
        help=HELP,
        description="Print what an MCAP recording holds: samples, gaps, channels, program, "
        "sensor, events, and how the recorder said the run went. Exit codes: 0 a complete "
        "file; 3 incomplete: the file is cut (imu-square recover rewrites what it holds) or "
        "the recorder marked the run incomplete (the 'run' line says why); 2 not a readable "
        "recording.",
    )
    p.add_argument("recording", help="MCAP file")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run)


def _text(path, summary):
    s = summary
    f = s["file"]
    state = (
        "complete"
        if f["complete"]
        else f"INCOMPLETE: {f['problem']}; read up to byte {f['cut_at_byte']} of {f['bytes']}"
    )
    lines = [
        f"{path}: {state}",
        f"  samples    {s['samples']} over {s['duration_s']:.3f} s at {s['sample_rate_hz']:.6g} Hz"
        f" (dt {s['dt_ns']} ns)",
        f"  gaps       {s['gaps']['count']} ({s['gaps']['lost']} samples lost)",
        f"  channels   {', '.join(s['channels'])}",
        "  messages   "
        + ", ".join(f"{topic} {n}" for topic, n in sorted(s["file"]["messages"].items())),
    ]
    prog = s["program"]
    if prog is None:
        lines.append("  program    none")
    elif "feeds_mm_per_min" in prog:
        feeds = ", ".join(
            f"{v:g} mm/min (period {t:.3f} s)"
            for v, t in zip(prog["feeds_mm_per_min"], prog["period_s"], strict=True)
        )
        lines.append(
            f"  program    r={prog['radius_mm']:g} mm, feeds {feeds}, "
            f"{prog['cycles_per_direction']} cycles, {prog['n_blocks']} blocks "
            f"({' '.join(prog['order'])} x {prog['runs']} per feed), {prog['duration_s']:.1f} s"
        )
    else:
        lines.append(
            f"  program    r={prog['radius_mm']:g} mm, v={prog['feed_mm_per_min']:g} mm/min, "
            f"{prog['cycles_per_direction']} cycles x {prog['n_blocks']} blocks "
            f"({' '.join(prog['order'])} x {prog['runs']}), period {prog['period_s']:.3f} s, "
            f"{prog['duration_s']:.1f} s"
        )
    sensor = s["sensor"]
    lines.append(
        f"  sensor     {sensor['model']}"
        + (f" #{sensor['serial']}" if sensor["serial"] else "")
        + (
            f", noise {sensor['noise_density_m_s2_rthz'] / UG:.3g} ug/rtHz"
            if sensor["noise_density_m_s2_rthz"] is not None
            else ""
        )
    )
    lines.append(f"  machine    {s['machine_id'] or '(not given)'}")
    run = s["run"]
    if run is not None:
        state = "complete" if run["complete"] else "INCOMPLETE: " + "; ".join(run["problems"])
        lines.append(f"  run        {state} (stop: {run['stop']})")
    events = s["events"]
    lines.append(
        "  events     " + (", ".join(f"{k} {n}" for k, n in events.items()) if events else "none")
    )
    return "\n".join(lines)


def run(args):
    """Print the summary of one recording on stdout."""
    contents = scan_mcap(args.recording)
    summary = summarize(contents.recording)
    report = contents.report
    summary["file"] = {
        "path": args.recording,
        "bytes": report.file_bytes,
        "complete": report.complete,
        "problem": contents.problem,
        "cut_at_byte": report.cut_at_byte,
        "messages": contents.channel_counts,
    }
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(_text(args.recording, summary))
    run = summary["run"]
    if not report.complete or (run is not None and not run["complete"]):
        return EXIT_INCOMPLETE
    return 0
