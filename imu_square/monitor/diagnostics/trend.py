"""Each diagnostic's trend over a machine's nights: its values, its change, its alarm.

:func:`judge_diagnostics` reads every night's fit under the monitor file's
diagnostic settings and, for each diagnostic of the set, gives every night
its value, its change against the diagnostic's baseline (:mod:`.baseline`,
from the nights of the machine's current baseline) and, for a diagnostic
with an alarm, the designed charts' state (:mod:`.alarms`). The charts run
over every night since the baseline that has a value, in recording-time
order, whatever the squareness's state that night (a backlash does not
depend on the sensor's thermal state or mounting). An alarm stands until a
new baseline is set, as the squareness's does: also when the diagnostic
settings change (the program's commanded motion, the effects, the software),
so that the fits it was found on are kept under another key; the diagnostic,
with no baseline under the new settings, carries the standing alarm and says
on which fits it fired.
"""

import math
from dataclasses import dataclass, replace

from imu_square.errors import MonitorError
from imu_square.log import logger
from imu_square.monitor.diagnostics.alarms import (
    describe,
    design_inputs,
    kept_design,
    stored_design,
)
from imu_square.monitor.diagnostics.baseline import MIN_NIGHTS, diagnostic_baseline
from imu_square.units import URAD

NO_FIT = "no diagnostic fit under the monitor file's [diagnostics]"


@dataclass(frozen=True)
class DiagnosticNight:
    """One diagnostic on one night.

    Attributes
    ----------
    run : RunRow
        The night's run.
    value, u_value : float
        The estimate and its standard uncertainty; NaN when missing. [SI]
    missing_reason : str
        Why it is missing; "" when it has a value.
    change, u_change : float
        Against the diagnostic's baseline, the change and its uncertainty
        (the night's with the baseline nights' scatter, the baseline's own
        error included); NaN without a baseline or before it. [SI]
    chart : ChartPoint or None
        What the alarm charts saw, for a diagnostic with an alarm.
    state : str
        ``"ok"``, ``"warning"`` or ``"alarm"`` for a charted night (``alarm``
        from the first alarm on); ``"baseline"`` for the baseline's nights; ""
        otherwise.
    """

    run: object
    value: float = math.nan
    u_value: float = math.nan
    missing_reason: str = ""
    change: float = math.nan
    u_change: float = math.nan
    chart: object = None
    state: str = ""


@dataclass(frozen=True)
class DiagnosticTrend:
    """One diagnostic over a machine's nights.

    Attributes
    ----------
    diagnostic : Diagnostic
        What it is.
    nights : tuple of DiagnosticNight
        Every valid night with a fit, in recording-time order.
    baseline : DiagnosticBaseline or None
        Its baseline, from the machine's current baseline's nights.
    design : AlarmDesign or None
        Its alarm's design, when it has one.
    step : float or None
        The change its alarm should find quickly. [SI]
    note : str
        Why it has no baseline or no alarm although one was asked; "" otherwise.
    alarm_since_ns : int or None
        When its standing alarm fired. [ns]
    fired_on : str
        The fits its standing alarm fired on, when under other diagnostic
        settings (e.g. "the motion 'trajectory'"); "" for these settings'.
    """

    diagnostic: object
    nights: tuple
    baseline: object = None
    design: object = None
    step: float | None = None
    note: str = ""
    alarm_since_ns: int | None = None
    fired_on: str = ""

    def night_of(self, run_id):
        """The night of a run, or None."""
        return next((n for n in self.nights if n.run.id == run_id), None)

    def describe_alarm(self):
        """The alarm's design in one line, or "" without one."""
        return "" if self.design is None else describe(self.design, self.diagnostic)


def judge_diagnostics(history, runs, baseline_row, settings, alarms):
    """Every diagnostic of the set over a machine's runs.

    Parameters
    ----------
    history : History
        The open history (the fits; an alarm's design is kept in it).
    runs : sequence of RunRow
        The machine's runs under the current analysis settings, in
        recording-time order.
    baseline_row : BaselineRow or None
        The machine's current baseline.
    settings : DiagnosticSettings
        The monitor file's ``[diagnostics]``.
    alarms : AlarmSettings
        The monitor file's ``[alarms]``.

    Returns
    -------
    tuple of DiagnosticTrend
        One per diagnostic of the set, in the catalog's order.
    """
    if not settings.enabled or not runs:
        return ()
    machine = runs[0].machine_id
    current = settings.key()
    trends = _trends(
        history, runs, history.diagnostic_fits(machine, current), baseline_row, settings, alarms
    )
    if baseline_row is None or all(t.baseline is not None for t in trends):
        return trends
    for key, stored in history.diagnostic_settings(machine).items():
        if key != current:
            fits = history.diagnostic_fits(machine, key)
            # judged on the design kept with the baseline only: reading them writes nothing
            other = _trends(None, runs, fits, baseline_row, settings, alarms)
            where = _settings_change(settings.stored(), stored)
            trends = tuple(_standing(t, o, where) for t, o in zip(trends, other, strict=True))
    return trends


def _trends(history, runs, fits, baseline_row, settings, alarms):
    """Each diagnostic's trend on some fits (``history`` None: no design is made or kept)."""
    valid = [r for r in runs if r.valid and r.id in fits]
    return tuple(
        _trend(history, d, valid, fits, baseline_row, settings, alarms)
        for d in settings.diagnostics()
    )


def _settings_change(now, then):
    """What other diagnostic settings fitted some nights, in a few words."""
    said = []
    if then.get("motion", "trajectory") != now.get("motion", "trajectory"):
        said.append(f"the motion {then.get('motion', 'trajectory')!r}")
    if then.get("software") != now.get("software"):
        said.append(f"software {then.get('software')}")
    if then.get("effects") != now.get("effects") or then.get("shapes") != now.get("shapes"):
        said.append(
            "other effects" if then.get("effects") != now.get("effects") else "other shapes"
        )
    return " and ".join(said) or "other settings"


def _standing(trend, other, where):
    """A diagnostic with no baseline, with the alarm standing on its fits under other settings.

    The machine has not changed with the settings: the alarm stands until a new
    baseline is set, its nights since it fired in alarm.
    """
    from imu_square.monitor.verdict import iso

    if trend.baseline is not None or other.alarm_since_ns is None:
        return trend
    if trend.alarm_since_ns is not None and trend.alarm_since_ns <= other.alarm_since_ns:
        return trend
    since = iso(other.alarm_since_ns)[:10]
    note = (
        f"{trend.note}; its alarm on the fits with {where} stands since {since}, until a new "
        "baseline is set"
    )
    nights = tuple(
        replace(n, state="alarm") if (n.run.recorded_at_ns or 0) >= other.alarm_since_ns else n
        for n in trend.nights
    )
    return replace(
        trend, nights=nights, note=note, alarm_since_ns=other.alarm_since_ns, fired_on=where
    )


def _night(run, fit, name):
    row = fit.value(name)
    if row is None:
        return DiagnosticNight(run, missing_reason=NO_FIT)
    if row.value is None:
        return DiagnosticNight(run, missing_reason=row.missing_reason)
    return DiagnosticNight(run, row.value, row.u_value)


def _trend(history, diagnostic, runs, fits, baseline_row, settings, alarms):
    step_si = settings.alarm_steps.get(diagnostic.name)
    nights = [_night(r, fits[r.id], diagnostic.name) for r in runs]
    if baseline_row is None:
        return DiagnosticTrend(diagnostic, tuple(nights), step=step_si)
    in_baseline = set(baseline_row.run_ids)
    base_nights = [n for n in nights if n.run.id in in_baseline and n.missing_reason == ""]
    baseline = diagnostic_baseline([n.value for n in base_nights], [n.u_value for n in base_nights])
    if baseline is None:
        note = _no_baseline_note(nights, in_baseline, settings.motion)
        return DiagnosticTrend(diagnostic, tuple(nights), step=step_si, note=note)
    design, note = None, ""
    if step_si is not None:
        try:
            inputs = design_inputs(diagnostic, baseline, step_si, alarms)
            if history is None:
                design = kept_design(baseline_row, diagnostic.name, inputs)
            else:
                design = stored_design(history, baseline_row, diagnostic.name, inputs)
        except MonitorError as exc:
            note = f"no alarm: {exc}"
            logger.warning("diagnostic %s: %s", diagnostic.name, note)
    start = baseline_row.first_run_at_ns or 0
    charted = []
    for i, n in enumerate(nights):
        if n.run.id in in_baseline:
            nights[i] = _with_change(n, baseline, "baseline")
        elif n.missing_reason == "" and (n.run.recorded_at_ns or 0) >= start:
            charted.append(i)
            nights[i] = _with_change(n, baseline, "")
    alarm_since = None
    if design is not None and charted:
        from imu_square.monitor.stats.alarms import run_charts

        # the design's angle fields are the diagnostic's shown unit times URAD (.alarms)
        run = run_charts(
            design,
            [nights[i].change / diagnostic.scale * URAD for i in charted],
            [_night_u(nights[i], baseline) / diagnostic.scale * URAD for i in charted],
            nu=design.nu,
        )
        for i, point in zip(charted, run.points, strict=True):
            state = point.state
            if alarm_since is not None:
                state = "alarm"
            elif state == "alarm":
                alarm_since = nights[i].run.recorded_at_ns
            nights[i] = replace(nights[i], chart=point, state=state)
    return DiagnosticTrend(
        diagnostic, tuple(nights), baseline, design, step_si, note, alarm_since_ns=alarm_since
    )


def _no_baseline_note(nights, in_baseline, motion):
    """Why a diagnostic has no baseline: its baseline's nights without a fit, or without a value.

    A fit is kept under the commanded motion its model ran, so the baseline's
    nights fitted under another motion have none under this one.
    """
    fitted = sum(n.run.id in in_baseline for n in nights)
    if fitted < MIN_NIGHTS:
        return (
            f"no baseline: {fitted} of the baseline's {len(in_baseline)} nights have a "
            f"diagnostic fit under these settings with the motion {motion!r} (a fit is kept "
            f"under the settings and motion it ran with): replay their recordings "
            f"('imu-square replay') with them, or set a new baseline"
        )
    return (
        f"no baseline: fewer than {MIN_NIGHTS} of the baseline's nights have a value: replay "
        f"their recordings ('imu-square replay') or set a new baseline"
    )


def _night_u(night, baseline):
    """A night's uncertainty for the charts: its own with the baseline nights' scatter. [SI]"""
    return math.hypot(night.u_value, baseline.between)


def _with_change(night, baseline, state):
    return replace(
        night,
        change=night.value - baseline.value,
        u_change=math.hypot(_night_u(night, baseline), baseline.u_value),
        state=state,
    )


def night_diagnostics(trends, run_id):
    """Each diagnostic on one night, for its record (shown units).

    Parameters
    ----------
    trends : sequence of DiagnosticTrend
        The machine's diagnostics.
    run_id : int
        The night's run.

    Returns
    -------
    dict of str to dict
        Diagnostic name to ``value``, ``u_value``, ``unit``, ``change``,
        ``u_change`` (None when missing), ``state`` ("" without an alarm) and
        ``missing_reason``; empty when the run has no fit.
    """
    out = {}
    for t in trends:
        n = t.night_of(run_id)
        if n is None:
            continue
        scale = t.diagnostic.scale
        out[t.diagnostic.name] = {
            "value": _shown(n.value, scale),
            "u_value": _shown(n.u_value, scale),
            "unit": t.diagnostic.unit,
            "change": _shown(n.change, scale),
            "u_change": _shown(n.u_change, scale),
            "state": n.state,
            "missing_reason": n.missing_reason or None,
        }
    return out


def alarm_clause(trends, run_id):
    """What the verdict line adds for the diagnostics in alarm on a night ("" for none)."""
    from imu_square.monitor.verdict import iso

    parts = []
    for t in trends:
        n = t.night_of(run_id)
        if n is not None and n.state == "alarm":
            d = t.diagnostic
            standing = ""
            if t.alarm_since_ns is not None and t.alarm_since_ns < (n.run.recorded_at_ns or 0):
                since = iso(t.alarm_since_ns)[:10]
                standing = f" (alarm since {since}, until a new baseline is set)"
            if t.fired_on:  # no change under these settings: it stands on the others' fits
                parts.append(
                    f"{d.name} (alarm on the fits with {t.fired_on} since "
                    f"{iso(t.alarm_since_ns)[:10]}, until a new baseline is set)"
                )
                continue
            parts.append(
                f"{d.name} {n.change / d.scale:+.3g} ± {n.u_change / d.scale:.2g} {d.unit} since "
                f"the baseline{standing}"
            )
    return f"; diagnostic alarm: {', '.join(parts)}: check the machine" if parts else ""


def _shown(x, scale):
    return x / scale if math.isfinite(x) else None
