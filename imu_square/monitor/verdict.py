"""The verdict on a machine's nights: from its history to a state, a change and the charts.

One function, :func:`judge_runs`, reads a machine's history (its current baseline,
the valid runs since it, the anchors) and gives every night since the baseline
its change (:mod:`.baseline`), the alarm charts' view of it (:mod:`.alarms`)
and a state:

- ``no_baseline``: no baseline has been set;
- ``stale_baseline``: the sensor was remounted (its ``eps_c`` jumped) since the
  baseline, so the sensor's own non-orthogonality may have changed: the
  change is no longer the machine's; set a new baseline. Never an alarm;
- ``invalid``: the run failed quality (it never enters a chart);
- ``ok``, ``warning``, ``alarm``: the designed charts' verdict.

The charts always run over every valid night since the baseline, in
recording-time order: the verdicts are a function of the history, so a
replay rebuilds them exactly, whatever order the runs were stored in.

**Thermal drift.** The machine does not change within a night, so a trend of
the per-cycle values within one (:func:`~.drift.fit_night_drift`, stored with
each run) is the sensor's. With a temperature channel, the within-night slopes
of every valid night up to the one judged (never a later one) are pooled,
inverse-variance weighted; when the pooled slope passes :data:`DRIFT_SIGNIFICANCE`
standard errors the night is corrected to the baseline runs' mean temperature
before its change is taken, and the slope's uncertainty enters the change's.
A night whose sensor warmed by more than :data:`WARMING_RISE_C` during the run,
or faster than :data:`WARMING_RATE_C_PER_MIN`, is not judged while that slope
is not known. Nights are never corrected by a regression *across* nights on
the temperature: it could not tell the sensor's drift from a machine change
that follows the season. Without a temperature channel a
linear slope against the time since power-on cannot be carried from a cold
night to a warm baseline: a night whose own within-night drift against it is
significant (p < :data:`WARMING_P`), or one switched on sooner than any of the
baseline's nights and within :data:`WARM_UP_S` of power-on, is not judged but
said to be warming up.
"""

import math
from dataclasses import dataclass, field, replace

import numpy as np

from imu_square.monitor.history.encoding import datetime_from_ns
from imu_square.monitor.stats.baseline import Baseline, RunValue, change_since
from imu_square.units import URAD

# The pooled within-night temperature slope corrects the nights past this many standard
# errors (a false correction one night in 370).
DRIFT_SIGNIFICANCE = 3.0
# Without a temperature channel, a night drifting this significantly is still warming up.
WARMING_P = 0.001
# A sensor whose temperature rises this much during the run is still warming up: the night
# is not judged while no drift slope is known (a seasonal change of the ambient leaves
# the run's own temperature steady, and is judged). [degC]
WARMING_RISE_C = 0.5
# ... and so is one whose temperature climbs faster than this, by at least the second
# figure (five steps of the wire's 0.01 °C): a short run can rise less than the figure
# above while its sensor, just switched on, is far from the baseline's temperature. The
# ambient changes by a few °C a day, hundreds of times slower. [degC/min], [degC]
WARMING_RATE_C_PER_MIN = 0.1
WARMING_MIN_RISE_C = 0.05
# Without a temperature channel, a night switched on sooner than any baseline night and
# within this time of power-on is not judged (MEMS sensors warm over minutes). [s]
WARM_UP_S = 1800.0


def iso(ns):
    """An integer-nanosecond UTC time as ISO 8601 (seconds), '' for None."""
    when = datetime_from_ns(ns)
    return "" if when is None else when.strftime("%Y-%m-%dT%H:%M:%SZ")


def run_value(row):
    """The :class:`~.baseline.RunValue` of a stored valid run."""
    return RunValue(
        squareness_rad=row.squareness_rad,
        u_squareness_rad=row.u_squareness_rad,
        dof=int(row.dof or 1),
        eps_c_rad=row.eps_c_rad,
        u_eps_c_rad=row.u_eps_c_rad,
        recorded_at=iso(row.recorded_at_ns),
    )


def baseline_of(row):
    """The :class:`~.baseline.Baseline` of a stored baseline row."""
    return Baseline(
        squareness_rad=row.squareness_mean_rad,
        sd_rad=row.squareness_sd_rad or 0.0,
        u_squareness_rad=row.u_squareness_mean_rad,
        dof=int(row.dof or 1),
        eps_c_rad=row.eps_c_rad,
        u_eps_c_rad=row.u_eps_c_rad,
        n_runs=len(row.run_ids),
        first_recorded_at=iso(row.first_run_at_ns),
        last_recorded_at=iso(row.last_run_at_ns),
    )


@dataclass(frozen=True)
class Night:
    """One run as the monitor judges it.

    Attributes
    ----------
    run : RunRow
        The stored run.
    state : str
        One of :data:`~imu_square.monitor.history.rows.EVALUATION_STATES`.
    change_rad, u_change_rad : float
        Change of the machine's squareness since the baseline and its standard
        uncertainty, baseline's included; NaN when there is none. [rad]
    chart : ChartPoint or None
        What the alarm charts saw (valid nights since the baseline).
    reason : str
        Why the state, in one line (the invalid run's reason, the remount, ...).
    drift : dict or None
        The drift correction applied to the night: the pooled within-night
        ``slope_rad_per_c`` and its ``u``, the night's and the reference
        temperature, and the ``correction_rad`` added to its ``theta_y - theta_x``.
    drift_corrected : bool
        Whether the change was corrected.
    stated : str
        For a night before the current baseline: the verdict line stored when
        it was judged (against the baseline of its time).
    """

    run: object
    state: str
    change_rad: float = math.nan
    u_change_rad: float = math.nan
    chart: object = None
    reason: str = ""
    drift: object = None
    drift_corrected: bool = False
    stated: str = ""


@dataclass(frozen=True)
class Assessment:
    """A machine's history judged against its current baseline.

    Attributes
    ----------
    machine_id : str
        The machine.
    baseline_row : BaselineRow or None
        The current baseline.
    design : AlarmDesign or None
        The alarm charts' design for that baseline.
    nights : tuple of Night
        Every run of the machine, in recording-time order.
    anchors : tuple of AnchorRow
        The baseline's anchors by reference methods.
    earlier : tuple of Assessment
        Each earlier baseline's own period judged against it, oldest first:
        its runs from its first run until the next baseline's.
    alarm_since_ns : int or None
        When the alarm that stands fired (the first alarm night since the
        current baseline); it stands until a new baseline is set. [ns]
    diagnostics : tuple of DiagnosticTrend
        Each diagnostic of the monitor file's set over the nights
        (:mod:`imu_square.monitor.diagnostics.trend`).
    """

    machine_id: str
    baseline_row: object
    design: object
    nights: tuple
    anchors: tuple = field(default=())
    earlier: tuple = field(default=())
    alarm_since_ns: int | None = None
    diagnostics: tuple = field(default=())

    @property
    def state(self):
        """The machine's state: ``alarm`` while an alarm stands, else its latest night's."""
        if self.alarm_since_ns is not None:
            return "alarm"
        return self.latest.state if self.latest else "no_baseline"

    @property
    def latest(self):
        """The last night, or None."""
        return self.nights[-1] if self.nights else None

    @property
    def anchor_rad(self):
        """The baseline's absolute machine squareness by its latest anchor, NaN if none. [rad]"""
        return self.anchors[-1].value_rad if self.anchors else math.nan

    def night_of(self, run_id):
        """The night of a stored run id, or None."""
        return next((n for n in self.nights if n.run.id == run_id), None)


def design_for(eps_c_rad, u_baseline_rad, runs, settings):
    """The alarm charts' design for a baseline.

    Parameters
    ----------
    eps_c_rad : float
        The baseline's sensor rotation. [rad]
    u_baseline_rad : float
        The baseline's standard uncertainty. [rad]
    runs : sequence of RunRow
        Its runs.
    settings : AlarmSettings
        The user's false-alarm rate and step.

    Returns
    -------
    AlarmDesign
    """
    from imu_square.monitor.stats.alarms import design_alarms

    c = abs(math.cos(2 * eps_c_rad))
    u = np.array([r.u_squareness_rad for r in runs]) / c
    sigma = float(np.median(u))
    dofs = [r.dof for r in runs if r.dof]
    nu = float(np.median(dofs)) if dofs else None
    ratio = min(u_baseline_rad / c / sigma, 2.0)
    return design_alarms(
        settings.false_alarm_nights,
        sigma,
        step_rad=settings.step_rad,
        nu=nu,
        baseline_sd_ratio=ratio,
        mc_nights=settings.monte_carlo_nights,
    )


def judge_runs(runs, baseline_row, design, anchors=(), earlier=None):
    """Judge every run of a machine against its current baseline.

    The baseline's own runs are its nights; runs recorded before its first run
    keep the verdict they had against the baseline of their time
    (``earlier``); every other valid run is charted, in recording-time order.
    An alarm stands until a new baseline is set: the charts restart after it
    (the zero state their run lengths assume), but the machine is not
    "unchanged" again until someone has looked at it and set a new baseline.

    Parameters
    ----------
    runs : sequence of RunRow
        All the machine's runs under the baseline's analysis settings, in
        recording-time order.
    baseline_row : BaselineRow or None
        The current baseline (stale or not).
    design : AlarmDesign or None
        Its alarm design; None when there is no baseline.
    anchors : sequence of AnchorRow
        The baseline's anchors.
    earlier : dict of int to EvaluationRow, optional
        Stored verdicts by run id, for the runs before the current baseline.

    Returns
    -------
    Assessment
    """
    from imu_square.monitor.stats.alarms import run_charts
    from imu_square.monitor.stats.baseline import remount_tolerance

    machine_id = runs[0].machine_id if runs else ""
    earlier = earlier or {}
    nights = {}
    if baseline_row is None:
        for r in runs:
            nights[r.id] = _invalid(r) if not r.valid else Night(r, "no_baseline")
        return Assessment(machine_id, None, None, tuple(nights[r.id] for r in runs), ())
    baseline = baseline_of(baseline_row)
    in_baseline = set(baseline_row.run_ids)
    base_runs = [r for r in runs if r.id in in_baseline]
    before = baseline_row.first_run_at_ns or 0
    tolerance = remount_tolerance([r.eps_c_rad for r in base_runs] or [baseline_row.eps_c_rad])
    serials = {_serial(r) for r in base_runs} - {""}
    corrections = _drift_corrections(runs, base_runs)
    charted, changes = [], []
    stale_since = baseline_row.stale_at_ns if baseline_row.stale else None
    stale_reason = baseline_row.stale_reason
    for r in runs:
        recorded = r.recorded_at_ns
        if not r.valid:
            nights[r.id] = _invalid(r)
            continue
        if r.id not in in_baseline and recorded is not None and recorded < before:
            nights[r.id] = _earlier(r, earlier.get(r.id))
            continue
        value = run_value(r)
        drift = corrections.get(r.id)
        if drift is not None and drift.get("warming") and r.id not in in_baseline:
            nights[r.id] = Night(r, "invalid", reason=drift["warming"], drift=drift)
            continue
        if drift is not None and drift["applied"]:
            value = replace(
                value,
                squareness_rad=value.squareness_rad + drift["correction_rad"],
                u_squareness_rad=math.hypot(value.u_squareness_rad, drift["u_correction_rad"]),
            )
        change = change_since(baseline, value, tolerance)
        corrected = bool(drift and drift["applied"])
        if r.id in in_baseline:
            nights[r.id] = Night(
                r, "ok", change.change_rad, change.u_change_rad, None, "baseline", drift, corrected
            )
            continue
        swapped = _serial(r) and serials and _serial(r) not in serials
        if (change.remounted or swapped) and stale_since is None:
            stale_since = recorded if recorded is not None else 0
            stale_reason = (
                f"the sensor was replaced (serial {_serial(r)}, the baseline's "
                f"{', '.join(sorted(serials))}): set a new baseline"
                if swapped
                else _remount_reason(change)
            )
        if stale_since is not None and (recorded is None or recorded >= stale_since):
            nights[r.id] = Night(
                r, "stale_baseline", change.change_rad, change.u_change_rad, None, stale_reason
            )
            continue
        charted.append((r, value, drift, corrected))
        changes.append(change)
    alarm_since = None
    if charted:
        c = abs(baseline.cos_2eps_c)
        chart_run = run_charts(
            design,
            [ch.change_rad for ch in changes],
            [v.u_squareness_rad / c for _, v, _, _ in charted],
            [float(r.dof) if r.dof else None for r, _, _, _ in charted],
        )
        for (r, _, drift, corrected), ch, point in zip(
            charted, changes, chart_run.points, strict=True
        ):
            notes = ["corrected for the sensor's thermal drift"] if corrected else []
            notes += _losses(r)
            state = point.state
            if alarm_since is not None:
                state = "alarm"
                notes.append(f"alarm since {iso(alarm_since)[:10]}, until a new baseline is set")
            elif state == "alarm":
                alarm_since = r.recorded_at_ns
            nights[r.id] = Night(
                r, state, ch.change_rad, ch.u_change_rad, point, "; ".join(notes), drift, corrected
            )
    return Assessment(
        machine_id,
        baseline_row,
        design,
        tuple(nights[r.id] for r in runs),
        tuple(anchors),
        alarm_since_ns=alarm_since,
    )


def _losses(row):
    """What a judged night lost, for its note: samples in gaps (a board gone included)."""
    quality = row.quality or {}
    lost = quality.get("lost_samples") or 0
    return [f"{lost} samples lost in {quality.get('gaps', 0)} gap(s)"] if lost else []


def _serial(row):
    """The sensor's serial number a run was recorded with, '' when unknown."""
    return str(((row.result or {}).get("sensor") or {}).get("serial", "") or "")


def _within(row):
    """A run's within-night drift fit as stored (``per_cycle["drift"]``), or None."""
    return (row.per_cycle or {}).get("drift")


def _run_minutes(row):
    """From the first sample to the middle of the last analysed cycle. [min]"""
    per_cycle = row.per_cycle or {}
    times = [t for key in ("t_ccw_s", "t_cw_s") for t in per_cycle.get(key) or () if t is not None]
    return max(times) / 60.0 if times else 0.0


def _drift_corrections(runs, base_runs):
    """Per valid run id, the drift correction or warm-up flag (module docstring)."""
    valid = [r for r in runs if r.valid]
    out = {}
    if base_runs and all(r.temperature_mean_c is not None for r in valid):
        reference = float(np.mean([r.temperature_mean_c for r in base_runs]))
        weight = weighted = 0.0
        for r in valid:  # recording-time order: each night sees only itself and earlier ones
            fit = _within(r)
            if fit and fit.get("regressor") == "temperature_c" and fit["u_slope_urad_per_unit"]:
                w = fit["u_slope_urad_per_unit"] ** -2
                weight += w
                weighted += w * fit["slope_urad_per_unit"]
            if weight == 0.0:
                continue
            slope, u_slope = weighted / weight * URAD, weight**-0.5 * URAD
            offset = reference - r.temperature_mean_c
            applied = abs(slope) > DRIFT_SIGNIFICANCE * u_slope
            out[r.id] = {
                "regressor": "temperature_c",
                "slope_rad_per_c": slope,
                "u_slope_rad_per_c": u_slope,
                "temperature_c": r.temperature_mean_c,
                "reference_c": reference,
                "correction_rad": slope * offset,
                "u_correction_rad": abs(offset) * u_slope,
                "applied": applied,
            }
        for r in valid:
            rise = (r.temperature_end_c or 0.0) - (r.temperature_start_c or 0.0)
            minutes = _run_minutes(r)
            rate = rise / minutes if minutes > 0 else 0.0
            warming = rise > WARMING_RISE_C or (
                rise >= WARMING_MIN_RISE_C and rate > WARMING_RATE_C_PER_MIN
            )
            if warming and not out.get(r.id, {}).get("applied"):
                out.setdefault(r.id, {"regressor": "temperature_c", "applied": False})
                out[r.id]["warming"] = (
                    f"the sensor was still warming up ({rise:+.2f} °C during the run, "
                    f"{rate:+.2f} °C/min) and its drift with the temperature is not known "
                    f"yet: not judged"
                )
        return out
    for r in valid:
        fit = _within(r)
        if fit and fit.get("regressor") == "time_since_power_on_s" and fit["p_value"] < WARMING_P:
            out[r.id] = _warming_up(
                f"the sensor was still warming up: theta_y - theta_x drifted "
                f"{fit['slope_urad_per_unit'] * 60:+.1f} µm/m a minute during the run "
                f"(p = {fit['p_value']:.1g}), {fit['reference']:.0f} s after power-on; "
                f"warm it up first, or give it a temperature channel"
            )
    # Without a temperature channel a drift that is not significant within a short run
    # can still hold hundreds of µm/m against warm baseline nights: a night switched on
    # sooner than any of them, and within the warm-up, is not judged.
    uptimes = [r.time_since_power_on_s for r in base_runs]
    if base_runs and all(u is not None for u in uptimes):
        soonest = min(min(uptimes), WARM_UP_S)
        for r in valid:
            up = r.time_since_power_on_s
            if r.id in out or up is None or up >= soonest:
                continue
            out[r.id] = _warming_up(
                f"the sensor was switched on {up / 60:.1f} min before the run, sooner than "
                f"any of the baseline's nights ({min(uptimes) / 60:.0f} min and more) and "
                f"within its first {WARM_UP_S / 60:.0f} min after power-on, and without a "
                f"temperature channel its warm-up drift cannot be corrected: warm it up "
                f"first, or give it a temperature channel"
            )
    return out


def _warming_up(reason):
    """A night without a temperature channel, not judged while its sensor warms up."""
    return {"regressor": "time_since_power_on_s", "applied": False, "warming": reason}


def _earlier(row, evaluation):
    """A run before the current baseline: its verdict of the time, if it was judged."""
    if evaluation is None:
        return Night(row, "no_baseline", reason="recorded before the current baseline")
    nan = math.nan
    stored = evaluation.statistics or {}
    return Night(
        row,
        evaluation.state,
        nan if evaluation.change_rad is None else evaluation.change_rad,
        nan if evaluation.u_change_rad is None else evaluation.u_change_rad,
        None,
        stored.get("reason") or "judged against an earlier baseline",
        stated=stored.get("verdict") or f"{evaluation.state}, judged against an earlier baseline",
    )


def _invalid(row):
    return Night(row, "invalid", reason=row.invalid_reason or "invalid")


def _remount_reason(change):
    # a controller's other ramps move eps_c too (0.05 deg on LinuxCNC's against ours)
    return (
        f"the sensor was remounted, or the test's motion changed: eps_c moved by "
        f"{math.degrees(change.eps_c_shift_rad):+.3f} deg; set a new baseline"
    )


def verdict(assessment, night):
    """The one-line verdict a user reads in the morning.

    Parameters
    ----------
    assessment : Assessment
        The machine's assessment.
    night : Night
        The night to state.

    Returns
    -------
    str
    """
    from imu_square.monitor.diagnostics.trend import alarm_clause

    line = _line(assessment, night)
    if machine_state(assessment, night) != night.state:
        line += (
            f"; the machine stands in alarm since {iso(assessment.alarm_since_ns)[:10]}, "
            f"until a new baseline is set"
        )
    if not night.stated:
        line += alarm_clause(assessment.diagnostics, night.run.id)
    return line


def machine_squareness(assessment, night):
    """The machine's absolute squareness on a night, by the anchored baseline.

    Parameters
    ----------
    assessment : Assessment
        The machine's assessment.
    night : Night
        The night.

    Returns
    -------
    tuple (float, float or None) or None
        The anchor's value plus the night's change, and its standard
        uncertainty (the anchor's and the change's combined; None when the
        anchor's was not given); None without an anchor or a change. [rad]
    """
    if not assessment.anchors or not math.isfinite(night.change_rad):
        return None
    anchor = assessment.anchors[-1]
    u = anchor.u_value_rad
    return anchor.value_rad + night.change_rad, None if u is None else math.hypot(
        u, night.u_change_rad
    )


def machine_state(assessment, night):
    """The machine's state on a night: ``alarm`` while an alarm stands, else the night's.

    An alarm stands from its night until a new baseline is set, whatever
    nights come after it: an invalid night then reports the alarm too.

    Parameters
    ----------
    assessment : Assessment
        The machine's assessment.
    night : Night
        The night.

    Returns
    -------
    str
    """
    standing = assessment.alarm_since_ns
    if standing is None or night.stated:
        return night.state
    recorded = night.run.recorded_at_ns
    return "alarm" if recorded is None or recorded >= standing else night.state


def _line(assessment, night):
    if night.stated:
        return night.stated
    since = ""
    if assessment.baseline_row is not None:
        base = assessment.baseline_row
        since = f" since the baseline of {iso(base.last_run_at_ns or base.created_at_ns)[:10]}"
    change = f"{night.change_rad / URAD:+.1f} ± {night.u_change_rad / URAD:.1f} µm/m (k=1)"
    absolute = ""
    anchored = machine_squareness(assessment, night)
    if anchored is not None:
        value, u = anchored
        absolute = (
            f"; machine squareness {value / URAD:+.1f} ± {u / URAD:.1f} µm/m (k=1)"
            if u is not None
            else f"; machine squareness {value / URAD:+.1f} µm/m (the anchor's u not given)"
        ) + " by the anchored baseline"
    if night.state == "ok":
        return f"squareness unchanged ({change}{since}){absolute}"
    if night.state == "warning":
        charts = ", ".join(night.chart.warnings) if night.chart else ""
        return (
            f"squareness may be changing: {change}{since}, {charts} past its warning limit"
            f"{absolute}"
        )
    if night.state == "alarm":
        charts = ", ".join(night.chart.alarms) if night.chart else ""
        why = f"{charts} alarm" if charts else night.reason
        return f"squareness changed by {change}{since} ({why}): check the machine{absolute}"
    if night.state == "invalid":
        return f"invalid run, not judged: {night.reason}"
    if night.state == "stale_baseline":
        return f"baseline stale: {night.reason}"
    if night.reason:
        return f"not judged: {night.reason}"
    return "no baseline yet: set one with 'imu-square baseline set' from at least 3 valid runs"
