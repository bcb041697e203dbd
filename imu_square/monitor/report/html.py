"""The monitor's report: one self-contained HTML page to show a manager.

Sections, each an ``<section id=...>``: the verdict, the trend chart, the
diagnostics (the latest night's, their trend chart and their alarms), the last
run in the paper's Fig. 5 style, the sensor (eps_c and temperature over time),
the baseline with its anchors, the alarm design, and the latest nights. Images
are PNGs inlined as ``data:`` URIs and the style is inline, so the page is one
file that opens anywhere, offline.
"""

import base64
import html
import math
import tempfile
from datetime import UTC, datetime
from pathlib import Path

from imu_square import __version__
from imu_square.monitor.verdict import iso, machine_squareness, verdict
from imu_square.units import URAD

SECTIONS = (
    "verdict",
    "trend",
    "diagnostics",
    "last-run",
    "sensor",
    "baseline",
    "alarm-design",
    "nights",
)
_CSS = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1150px; color: #222;
       padding: 0 1em; box-sizing: border-box; overflow-wrap: anywhere; }
h1 { font-size: 1.5em; } h2 { font-size: 1.15em; border-bottom: 1px solid #ccc; }
.verdict { font-size: 1.2em; padding: 0.7em 1em; border-radius: 6px; }
.ok { background: #e6f4ea; } .warning { background: #fff4e0; } .alarm { background: #fde7e7; }
.invalid, .stale_baseline, .no_baseline { background: #eee; }
img { max-width: 100%; height: auto; } pre { white-space: pre-wrap; }
.table { overflow-x: auto; } table { border-collapse: collapse; font-size: 0.9em; }
td, th { border: 1px solid #ddd; padding: 0.25em 0.6em; text-align: right; }
td.text, th.text { text-align: left; } .muted { color: #777; }
"""


def _png(write):
    """The PNG that ``write(path)`` draws, as a data URI."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "figure.png"
        write(path)
        return "data:image/png;base64," + base64.b64encode(path.read_bytes()).decode("ascii")


def _e(text):
    return html.escape(str(text), quote=True)


def _num(x, fmt="+.1f"):
    return "–" if x is None or not math.isfinite(x) else format(x, fmt)


def render_report(assessment, last_result=None, last_title="", now=None):
    """The report as HTML text.

    Parameters
    ----------
    assessment : Assessment
        The machine's history judged against its current baseline.
    last_result : RunResult, optional
        The analysis of the latest valid run, drawn in the paper's Fig. 5 style.
    last_title : str
        What that run is (its recording), for its figure.
    now : datetime, optional
        When the report is made (UTC); the present if None.

    Returns
    -------
    str
        One self-contained HTML page.
    """
    from imu_square.monitor.report.figures import plot_sensor, plot_trend

    now = now or datetime.now(UTC)
    machine = assessment.machine_id
    latest = assessment.latest
    state = assessment.state
    line = verdict(assessment, latest) if latest else "no runs yet"
    trend = _png(lambda p: plot_trend(assessment, p))
    sensor = _png(lambda p: plot_sensor(assessment, p))
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>imu-square report: {_e(machine)}</title>",
        f"<style>{_CSS}</style></head><body>",
        f"<h1>Squareness monitor: machine {_e(machine)}</h1>",
        f'<p class="muted">Report of {now.strftime("%Y-%m-%d %H:%M")} UTC, imu-square '
        f"{_e(__version__)}. The change is that of theta_y − theta_x (paper, Eq. 4) since the "
        "machine's baseline, divided by cos 2eps_c: the machine's own change, the sensor's "
        "cancelling.</p>",
        '<section id="verdict"><h2>Verdict</h2>',
        f'<p class="verdict {_e(state)}">{_e(line)}</p>',
        f'<p class="muted">last run: {_e(iso(latest.run.recorded_at_ns) if latest else "–")}'
        f", state <b>{_e(state)}</b></p></section>",
        '<section id="trend"><h2>Trend</h2>',
        f'<img alt="trend chart of the change since the baseline" src="{trend}"></section>',
        '<section id="diagnostics"><h2>Diagnostics</h2>',
        _diagnostics_html(assessment),
        "</section>",
        '<section id="last-run"><h2>Last valid run</h2>',
    ]
    if last_result is not None:
        from imu_square.pipeline.run_figure import plot_results

        fig = _png(lambda p: plot_results([last_result], p, title=Path(last_title).name))
        parts += [
            f"<p>{_e(last_title)}</p><pre>{_e(last_result.summary())}</pre>",
            f'<img alt="flipped, averaged and fitted traces of the last run" src="{fig}">',
        ]
    else:
        parts.append('<p class="muted">No valid run whose recording is still on disk.</p>')
    parts += [
        "</section>",
        '<section id="sensor"><h2>Sensor</h2>',
        f'<img alt="eps_c and temperature over time" src="{sensor}"></section>',
        '<section id="baseline"><h2>Baseline and anchors</h2>',
        _baseline_html(assessment),
        "</section>",
        '<section id="alarm-design"><h2>Alarm design</h2>',
        _design_html(assessment.design),
        "</section>",
        '<section id="nights"><h2>Latest nights</h2>',
        _nights_html(assessment),
        "</section></body></html>",
    ]
    return "\n".join(parts) + "\n"


def _diagnostics_html(assessment):
    """The latest night's diagnostics, their alarms' designs and their trend chart."""
    from imu_square.monitor.diagnostics.text import value_text
    from imu_square.monitor.report.diagnostics_figure import plot_diagnostics

    trends = assessment.diagnostics
    if not trends:
        return "<p>No diagnostics: the monitor file's [diagnostics] fits no effect.</p>"
    last = next(
        (n for n in reversed(assessment.nights) if any(t.night_of(n.run.id) for t in trends)),
        None,
    )
    head = (
        "<tr><th class='text'>diagnostic</th><th class='text'>what it is</th><th>value</th>"
        "<th>change since the baseline</th><th class='text'>alarm</th></tr>"
    )
    rows = []
    for t in trends:
        d = t.diagnostic
        n = None if last is None else t.night_of(last.run.id)
        value = change = n.missing_reason if n is not None and n.missing_reason else "–"
        if n is not None and not n.missing_reason:
            value = f"{value_text(n.value / d.scale, n.u_value / d.scale)} {d.unit}"
            if math.isfinite(n.change):
                change = f"{value_text(n.change / d.scale, n.u_change / d.scale)} {d.unit}"
        alarm = "off" if t.step is None else "not judged"  # asked, but no design
        if t.design is not None:
            alarm = n.state if n is not None else ""
        elif t.fired_on:  # standing on the fits under other settings
            alarm = "alarm"
        # the note says why there is no baseline or alarm, whatever the alarm's state
        said = "; ".join(x for x in (alarm, t.note) if x)
        css = alarm if alarm in ("ok", "warning", "alarm") else ""
        rows.append(
            f"<tr><td class='text'>{_e(d.name)}</td><td class='text'>{_e(d.meaning)}</td>"
            f"<td>{_e(value)}</td><td>{_e(change)}</td>"
            f"<td class='text {css}'>{_e(said)}</td></tr>"
        )
    when = iso(last.run.recorded_at_ns) if last is not None else "–"
    designs = "".join(f"<li>{_e(t.describe_alarm())}</li>" for t in trends if t.design)
    chart = _png(lambda p: plot_diagnostics(assessment, p))
    return (
        f"<p>The effects a ballbar reports, fitted to every valid night's recording; the "
        f"latest night's ({_e(when)}), with their standard uncertainties (k=1):</p>"
        f'<div class="table"><table>{head}{"".join(rows)}</table></div>'
        + (f"<p>Alarms:</p><ul>{designs}</ul>" if designs else "")
        + f'<img alt="trend chart of the diagnostics" src="{chart}">'
    )


def _baseline_html(assessment):
    b = assessment.baseline_row
    if b is None:
        return "<p>No baseline yet: <code>imu-square baseline set</code> from 3 valid runs.</p>"
    rows = [
        ("θy − θx of the baseline", f"{b.squareness_mean_rad / URAD:+.2f} µm/m"),
        ("its standard uncertainty", f"{b.u_squareness_mean_rad / URAD:.2f} µm/m"),
        ("spread of its runs (sd)", f"{(b.squareness_sd_rad or 0.0) / URAD:.2f} µm/m"),
        ("eps_c", f"{math.degrees(b.eps_c_rad):.3f} ± {math.degrees(b.u_eps_c_rad):.3f}°"),
        ("runs", f"{len(b.run_ids)}, {iso(b.first_run_at_ns)} to {iso(b.last_run_at_ns)}"),
        ("set", iso(b.created_at_ns)),
        ("state", f"stale: {b.stale_reason}" if b.stale else "current"),
    ]
    for a in assessment.anchors:
        u = "" if a.u_value_rad is None else f" ± {a.u_value_rad / URAD:.1f}"
        rows.append(
            (f"anchor by {a.method}", f"{a.value_rad / URAD:+.1f}{u} µm/m ({iso(a.created_at_ns)})")
        )
    body = "".join(f'<tr><th class="text">{_e(k)}</th><td>{_e(v)}</td></tr>' for k, v in rows)
    return f'<div class="table"><table>{body}</table></div>'


def _design_html(design):
    if design is None:
        return "<p>No alarm design without a baseline.</p>"
    d = design.to_json_dict()
    rows = [
        ("asked: one false alarm in", f"{d['arl0_nights']:g} nights"),
        ("σ of one night's change", f"{d['sigma_urad']:.2f} µm/m"),
        ("Shewhart limit |z|", f"{design.shewhart.limit:.2f}"),
        ("EWMA λ, limit", f"{design.ewma.parameter:.2f}, {design.ewma.limit:.3f}"),
        ("CUSUM k, h", f"{design.cusum.parameter:.2f}, {design.cusum.limit:.2f}"),
    ]
    body = "".join(f'<tr><th class="text">{_e(k)}</th><td>{_e(v)}</td></tr>' for k, v in rows)
    return f'<p>{_e(design.describe())}</p><div class="table"><table>{body}</table></div>'


def _nights_html(assessment, last=30):
    head = (
        "<tr><th class='text'>recorded</th><th class='text'>state</th><th>change µm/m</th>"
        "<th>u µm/m</th><th>θy − θx µm/m</th><th>eps_c °</th><th>machine µm/m</th>"
        "<th class='text'>note</th></tr>"
    )
    rows = []
    for n in reversed(assessment.nights[-last:]):
        r = n.run
        eps = None if r.eps_c_rad is None else math.degrees(r.eps_c_rad)
        sq = None if r.squareness_rad is None else r.squareness_rad / URAD
        anchored = machine_squareness(assessment, n)
        absolute = "–"
        if anchored is not None:
            value, u = anchored
            absolute = f"{value / URAD:+.1f}" + ("" if u is None else f" ± {u / URAD:.1f}")
        rows.append(
            f"<tr><td class='text'>{_e(iso(r.recorded_at_ns))}</td>"
            f"<td class='text {_e(n.state)}'>{_e(n.state)}</td>"
            f"<td>{_num(n.change_rad / URAD)}</td><td>{_num(n.u_change_rad / URAD, '.1f')}</td>"
            f"<td>{_num(sq)}</td><td>{_num(eps, '.3f')}</td><td>{_e(absolute)}</td>"
            f"<td class='text'>{_e(n.reason)}</td></tr>"
        )
    return f'<div class="table"><table>{head}{"".join(rows)}</table></div>'


def write_report(path, text):
    """Write the report atomically (a reader never sees half a page).

    Parameters
    ----------
    path : str or Path
        The HTML file.
    text : str
        The page.
    """
    from imu_square.io.atomic import write_atomic

    write_atomic(Path(path), text.encode("utf-8"))
