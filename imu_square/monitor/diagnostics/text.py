"""The diagnostics as text for people: a table of the nights, one column a diagnostic."""

import math

from imu_square.monitor.verdict import iso

# A cell's mark for a night past a diagnostic's warning or alarm limit.
MARKS = {"alarm": "!", "warning": "?"}


def value_text(value, u):
    """``value±u`` to the uncertainty's second significant digit (shown units)."""
    decimals = 0 if not u > 0 else min(max(1 - math.floor(math.log10(u)), 0), 8)
    return f"{value:+.{decimals}f}±{u:.{decimals}f}"


def _cell(night, diagnostic):
    if night is None or not math.isfinite(night.value):
        return "–"
    s = diagnostic.scale
    return value_text(night.value / s, night.u_value / s) + MARKS.get(night.state, "")


def table_lines(trends, runs):
    """The diagnostics of some nights as the lines of a table.

    Parameters
    ----------
    trends : sequence of DiagnosticTrend
        The machine's diagnostics.
    runs : sequence of RunRow
        The nights to show, in order; those without a fit are left out.

    Returns
    -------
    list of str
        A header naming each diagnostic with its unit, then one line per
        night: each diagnostic's value ± its standard uncertainty, ``!`` past
        its alarm limit, ``?`` past its warning limit, ``–`` when missing; a
        last line names the diagnostics in alarm. Empty without diagnostics.
    """
    if not trends:
        return []
    heads = [f"{t.diagnostic.name} {t.diagnostic.unit}" for t in trends]
    width = max(14, *(len(h) for h in heads))
    lines = [f"{'run':>5}  {'recorded':20}  " + "  ".join(f"{h:>{width}}" for h in heads)]
    for r in runs:
        nights = [t.night_of(r.id) for t in trends]
        if all(n is None for n in nights):
            continue
        cells = [_cell(n, t.diagnostic) for n, t in zip(nights, trends, strict=True)]
        lines.append(
            f"{r.id:>5}  {iso(r.recorded_at_ns):20}  " + "  ".join(f"{c:>{width}}" for c in cells)
        )
    standing = [
        f"{t.diagnostic.name} since {iso(t.alarm_since_ns)[:10]}"
        for t in trends
        if t.alarm_since_ns is not None
    ]
    if standing:
        lines.append(f"diagnostic alarms standing: {', '.join(standing)}")
    return lines


def note_lines(trends, nights, motion):
    """Why some diagnostics have no value or no baseline, one line each.

    Parameters
    ----------
    trends : sequence of DiagnosticTrend
        The machine's diagnostics.
    nights : sequence of Night
        The nights shown, in order.
    motion : str
        The commanded motion the diagnostics' fits are read under.

    Returns
    -------
    list of str
        A line for the judged nights (not ``invalid``) shown that have no
        diagnostic fit under these settings, naming their runs; then each
        distinct note of the diagnostics (:attr:`DiagnosticTrend.note`) with
        the diagnostics it holds for. Empty without diagnostics or notes.
    """
    if not trends:
        return []
    fitted = {n.run.id for t in trends for n in t.nights}
    unfitted = [n.run.id for n in nights if n.state != "invalid" and n.run.id not in fitted]
    lines = []
    if unfitted:
        ids = ", ".join(map(str, unfitted[:6])) + (", …" if len(unfitted) > 6 else "")
        lines.append(
            f"{len(unfitted)} judged night(s) have no diagnostic fit under these settings with "
            f"the motion {motion!r} (runs {ids}): replay their recordings ('imu-square replay') "
            "with them"
        )
    by_note = {}
    for t in trends:
        if t.note:
            by_note.setdefault(t.note, []).append(t.diagnostic.name)
    for note, names in by_note.items():
        who = "every diagnostic" if len(names) == len(trends) else ", ".join(names)
        lines.append(f"{who}: {note}")
    return lines
