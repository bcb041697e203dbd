"""The verdict on a machine's nights: from its history to a state, a change and the charts.

One function, :func:`assess`, reads a machine's history (its current baseline,
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

**Thermal drift across nights.** Each night's ``theta_y - theta_x`` is
regressed, with the baseline's runs and every valid night before it (never a
later one), on the sensor's mean temperature during the run, or without a
temperature channel on its time since power-on, capped at :data:`UPTIME_CAP_S`
(:func:`~.drift.fit_run_drift`).
When that slope is significant (p < :data:`DRIFT_P`, at least
:data:`DRIFT_MIN_RUNS` runs) the night is corrected to the baseline's mean
temperature (or uptime) before its change is taken, and the slope's
uncertainty enters the change's. A machine change that is independent of the
temperature adds scatter but no slope; one that follows it is partly taken for
drift, which is why the correction needs significance and is reported.
"""

import math
from dataclasses import dataclass, field, replace

import numpy as np

from imu_square.monitor.baseline import Baseline, RunValue, change_since
from imu_square.monitor.encoding import datetime_from_ns
from imu_square.units import URAD

STATES = ("ok", "warning", "alarm", "invalid", "stale_baseline", "no_baseline")
# The across-night drift correction needs this many runs and a slope this significant.
DRIFT_MIN_RUNS = 8
DRIFT_P = 0.01
# A sensor warms up in minutes to an hour; beyond this its uptime says nothing more, and
# an uptime that grows night after night (a board never switched off) must not stand in
# for the calendar, or a slow change of the machine would be taken for drift. [s]
UPTIME_CAP_S = 6 * 3600.0


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
        One of :data:`STATES`.
    change_rad, u_change_rad : float
        Change of the machine's squareness since the baseline and its standard
        uncertainty, baseline's included; NaN when there is none. [rad]
    chart : ChartPoint or None
        What the alarm charts saw (valid nights since the baseline).
    reason : str
        Why the state, in one line (the invalid run's reason, the remount, ...).
    drift : DriftFit or None
        The across-night drift regression up to this night, when one could be fitted.
    drift_corrected : bool
        Whether the change was corrected for it.
    """

    run: object
    state: str
    change_rad: float = math.nan
    u_change_rad: float = math.nan
    chart: object = None
    reason: str = ""
    drift: object = None
    drift_corrected: bool = False


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
    """

    machine_id: str
    baseline_row: object
    design: object
    nights: tuple
    anchors: tuple = field(default=())

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


def design_for(baseline_row, runs, settings):
    """The alarm charts' design for a baseline.

    Parameters
    ----------
    baseline_row : BaselineRow
        The baseline.
    runs : sequence of RunRow
        Its runs.
    settings : AlarmSettings
        The user's false-alarm rate and step.

    Returns
    -------
    AlarmDesign
    """
    from imu_square.monitor.alarms import design_alarms

    c = abs(math.cos(2 * baseline_row.eps_c_rad))
    u = np.array([r.u_squareness_rad for r in runs]) / c
    sigma = float(np.median(u))
    dofs = [r.dof for r in runs if r.dof]
    nu = float(np.median(dofs)) if dofs else None
    ratio = min(baseline_row.u_squareness_mean_rad / c / sigma, 2.0)
    return design_alarms(
        settings.false_alarm_nights,
        sigma,
        step_rad=settings.step_rad,
        nu=nu,
        baseline_sd_ratio=ratio,
        mc_nights=settings.monte_carlo_nights,
    )


def assess(runs, baseline_row, design, anchors=(), earlier=None):
    """Judge every run of a machine against its current baseline.

    Runs recorded before the current baseline's first run keep the verdict
    they had against the baseline of their time (``earlier``). Since the
    baseline, an alarm stands until a new baseline is set: the charts restart
    after it (the zero state their run lengths assume), but the machine is not
    "unchanged" again until someone has looked at it and set a new baseline.

    Parameters
    ----------
    runs : sequence of RunRow
        All the machine's runs, in recording-time order.
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
    from imu_square.monitor.alarms import evaluate

    machine_id = runs[0].machine_id if runs else ""
    earlier = earlier or {}
    nights = {}
    if baseline_row is None:
        for r in runs:
            nights[r.id] = _invalid(r) if not r.valid else Night(r, "no_baseline")
        return Assessment(machine_id, None, None, tuple(nights[r.id] for r in runs), ())
    baseline = baseline_of(baseline_row)
    in_baseline = set(baseline_row.run_ids)
    before = baseline_row.first_run_at_ns or 0
    after = baseline_row.last_run_at_ns or 0
    drift_fits = _drift_fits(runs, in_baseline, after)
    charted, changes = [], []
    stale_since = baseline_row.stale_at_ns if baseline_row.stale else None
    for r in runs:
        if not r.valid:
            nights[r.id] = _invalid(r)
            continue
        if r.id not in in_baseline and (r.recorded_at_ns or 0) < before:
            nights[r.id] = _earlier(r, earlier.get(r.id))
            continue
        value = run_value(r)
        fit, corrected = drift_fits.get(r.id, (None, False))
        if corrected:
            x = _drift_x(r, fit.regressor)
            value = replace(
                value,
                squareness_rad=float(fit.corrected(value.squareness_rad, x)),
                u_squareness_rad=math.hypot(
                    value.u_squareness_rad, (x - fit.reference) * fit.u_slope_rad_per_unit
                ),
            )
        change = change_since(baseline, value)
        if r.id in in_baseline or (r.recorded_at_ns or 0) <= after:
            nights[r.id] = Night(
                r, "ok", change.change_rad, change.u_change_rad, None, "baseline", fit, corrected
            )
            continue
        if change.remounted and stale_since is None:
            stale_since = r.recorded_at_ns or 0
        if stale_since is not None and (r.recorded_at_ns or 0) >= stale_since:
            reason = baseline_row.stale_reason or _remount_reason(change)
            nights[r.id] = Night(
                r, "stale_baseline", change.change_rad, change.u_change_rad, None, reason
            )
            continue
        charted.append((r, value, fit, corrected))
        changes.append(change)
    if charted:
        c = abs(baseline.cos_2eps_c)
        evaluation = evaluate(
            design,
            [ch.change_rad for ch in changes],
            [v.u_squareness_rad / c for _, v, _, _ in charted],
            [float(r.dof) if r.dof else None for r, _, _, _ in charted],
        )
        alarm_since = None
        for (r, _, fit, corrected), ch, point in zip(
            charted, changes, evaluation.points, strict=True
        ):
            notes = ["corrected for the sensor's thermal drift"] if corrected else []
            state = point.state
            if alarm_since is not None:
                state = "alarm"
                notes.append(f"alarm since {iso(alarm_since)[:10]}, until a new baseline is set")
            elif state == "alarm":
                alarm_since = r.recorded_at_ns
            nights[r.id] = Night(
                r, state, ch.change_rad, ch.u_change_rad, point, "; ".join(notes), fit, corrected
            )
    return Assessment(
        machine_id, baseline_row, design, tuple(nights[r.id] for r in runs), tuple(anchors)
    )


def _drift_x(row, regressor):
    """A run's drift variable: its mean temperature, or its uptime at its middle, capped
    at :data:`UPTIME_CAP_S`. [degC or s]"""
    if regressor == "temperature_c":
        return row.temperature_mean_c
    result = row.result or {}
    ends = [result.get("per_cycle", {}).get(k) or [] for k in ("t_ccw_s", "t_cw_s")]
    middle = float(np.mean(ends[0] + ends[1])) if ends[0] or ends[1] else 0.0
    return min(row.time_since_power_on_s + middle, UPTIME_CAP_S)


def _drift_fits(runs, in_baseline, after_ns):
    """For each valid run, the across-night drift fit on it and the runs before, and
    whether it corrects the run: ``{run_id: (DriftFit, bool)}``."""
    from imu_square.errors import AnalysisError
    from imu_square.monitor.drift import fit_run_drift

    valid = [r for r in runs if r.valid]
    if all(r.temperature_mean_c is not None for r in valid):
        regressor = "temperature_c"
    elif all(r.time_since_power_on_s is not None for r in valid):
        regressor = "time_since_power_on_s"
    else:
        return {}
    base = [r for r in valid if r.id in in_baseline]
    if not base:
        return {}
    x_ref = float(np.mean([_drift_x(r, regressor) for r in base]))
    later = [r for r in valid if r.id not in in_baseline and (r.recorded_at_ns or 0) > after_ns]
    out = {}
    for k in range(len(later) + 1):
        used = base + later[:k]
        if len(used) < 3:
            continue
        try:
            fit = fit_run_drift(
                [r.squareness_rad for r in used],
                [r.u_squareness_rad for r in used],
                [_drift_x(r, regressor) for r in used],
                regressor,
                reference=x_ref,
            )
        except AnalysisError:  # the variable does not vary yet
            continue
        apply = len(used) >= DRIFT_MIN_RUNS and fit.p_value < DRIFT_P
        target = later[k - 1] if k else None
        if target is not None:
            out[target.id] = (fit, apply)
        else:
            for r in base:
                out[r.id] = (fit, False)
    return out


def _earlier(row, evaluation):
    """A run before the current baseline: its verdict of the time, if it was judged."""
    if evaluation is None:
        return Night(row, "no_baseline", reason="before the current baseline")
    nan = math.nan
    return Night(
        row,
        evaluation.state,
        nan if evaluation.change_rad is None else evaluation.change_rad,
        nan if evaluation.u_change_rad is None else evaluation.u_change_rad,
        None,
        "judged against an earlier baseline",
    )


def _invalid(row):
    return Night(row, "invalid", reason=row.invalid_reason or "invalid")


def _remount_reason(change):
    return (
        f"the sensor was remounted: eps_c moved by "
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
    since = ""
    if assessment.baseline_row is not None:
        base = assessment.baseline_row
        since = f" since the baseline of {iso(base.last_run_at_ns or base.created_at_ns)[:10]}"
    change = f"{night.change_rad / URAD:+.1f} ± {night.u_change_rad / URAD:.1f} µm/m (k=1)"
    absolute = ""
    if math.isfinite(assessment.anchor_rad) and math.isfinite(night.change_rad):
        value = (assessment.anchor_rad + night.change_rad) / URAD
        absolute = f"; machine squareness {value:+.1f} µm/m by the anchored baseline"
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
    return "no baseline yet: set one with 'imu-square baseline set' from at least 3 valid runs"
