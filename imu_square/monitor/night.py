"""One night of the monitor: a recording in, a stored run, a verdict and its record out.

:func:`judge_recording` analyses a recording and fits its diagnostics
(:mod:`imu_square.monitor.diagnostics`), stores both in the history (a run
that cannot be trusted as an invalid run with its one-line reason), marks the
baseline stale on a sensor remount, runs the alarm charts over the history
and stores the night's verdict and its pending alerts, in one transaction.
It never prints: the ``nightly`` and ``replay`` commands report what it
returns.
"""

import math
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path

import numpy as np

from imu_square import __version__
from imu_square.errors import (
    AnalysisError,
    HistoryError,
    ImuSquareError,
    MonitorError,
    RecordingError,
    step,
)
from imu_square.io.times import is_date
from imu_square.json_values import json_safe
from imu_square.log import logger
from imu_square.monitor.alerts.send import queue_alert
from imu_square.monitor.diagnostics.trend import judge_diagnostics, night_diagnostics
from imu_square.monitor.history.encoding import file_sha256, first_line, settings_hash
from imu_square.monitor.history.rows import RUN_FLOAT_FIELDS, EvaluationRow, RunRow
from imu_square.monitor.stats.drift import fit_night_drift, power_on_offset_s
from imu_square.monitor.verdict import (
    design_for,
    iso,
    judge_runs,
    machine_squareness,
    machine_state,
    verdict,
)
from imu_square.units import MM_PER_MIN, URAD


@dataclass(frozen=True)
class NightOutcome:
    """What one night gave.

    Attributes
    ----------
    run_id : int
        The run's row in the history.
    inserted : bool
        False when the same recording under the same settings was there already.
    state : str
        The verdict's state (:data:`~imu_square.monitor.history.rows.EVALUATION_STATES`).
    verdict : str
        The one line a user reads in the morning.
    record : dict
        The night's record for ``--json`` and the alert sinks.
    assessment : Assessment
        The machine's whole history as judged now.
    result : RunResult or None
        The analysis, None for an invalid run.
    alert : Alert or None
        The night's alert, pending in the outbox; None when none was made.
    """

    run_id: int
    inserted: bool
    state: str
    verdict: str
    record: dict
    assessment: object
    result: object = None
    alert: object = None


#: The data folder's list of recordings a busy or unreachable history could not take.
KEPT_NIGHTS = "nights-to-store.txt"


def analysis_settings(config):
    """The analysis settings stored with every run (their hash keys a run). [JSON]"""
    return {"analysis": asdict(config.analysis.options()), "software": __version__}


def run_row(config, path, recording=None, result=None, reason=None, sha256=None, notes=()):
    """The history row of one recording, valid or invalid.

    Parameters
    ----------
    config : MonitorConfig
        The monitor file.
    path : str or Path
        The recording.
    recording : Recording or None
        The recording as read (None when it could not be read).
    result : RunResult or None
        Its analysis (None for an invalid run).
    reason : str or None
        Why the run is invalid.
    sha256 : str, optional
        The file's SHA-256, when the caller has it already.
    notes : sequence of str
        What the reading found missing; they lead the run's warnings.

    Returns
    -------
    RunRow
    """
    if recording is not None:
        recorded = int(recording.time_ns[0])
    else:  # unreadable: its file's time, so that it sorts where it arrived, not last
        recorded = Path(path).stat().st_mtime_ns
    base = {
        "machine_id": config.machine_id,
        "recording_path": str(path),
        "recording_sha256": sha256 or file_sha256(path),
        "settings": analysis_settings(config),
        "recorded_at_ns": recorded,
    }
    temps = {}
    uptime = None
    if recording is not None:
        uptime = power_on_offset_s(recording)
        if recording.temperature_c is not None and recording.temperature_c.size:
            t = recording.temperature_c
            temps = {
                "temperature_start_c": float(t[0]),
                "temperature_end_c": float(t[-1]),
                "temperature_mean_c": float(np.mean(t)),
            }
    if result is None:
        return RunRow(
            **base, valid=False, invalid_reason=reason, time_since_power_on_s=uptime, **temps
        )
    doc = result.to_json_dict()
    doc["sensor"] = {"model": recording.sensor.model, "serial": recording.sensor.serial}
    drift = None
    try:
        drift = fit_night_drift(result, recording).to_json_dict()
    except AnalysisError:
        pass  # too few cycles or a constant regressor: no within-night slope
    per_cycle = dict(doc["per_cycle"], drift=drift)
    named = {f.name for f in fields(result)}  # the run's numbers the result holds by name
    return RunRow(
        **base,
        **{name: getattr(result, name) for name in RUN_FLOAT_FIELDS if name in named},
        valid=True,
        dof=float(result.u_squareness_dof),
        time_since_power_on_s=uptime,
        cycles_ccw=result.cycles_used["ccw"],
        cycles_cw=result.cycles_used["cw"],
        quality={k: v for k, v in doc["quality"].items() if k != "warnings"},
        warnings=(*notes, *result.quality["warnings"]),
        per_cycle=per_cycle,
        result=doc,
        **temps,
    )


def analyse_recording(config, path, program=None, keep_unreadable=True):
    """Read and analyse a recording, or say in one line why it cannot be trusted.

    A recording with samples lost (gaps, a board gone before the end, a file
    cut short) is judged whenever the analysis accepts it: what was lost is
    noted with the night. Only a run the analysis refuses is invalid.

    Parameters
    ----------
    config : MonitorConfig
        The monitor file (analysis settings).
    path : str or Path
        The recording.
    program : TestProgram, optional
        The program the monitor expects; a recording of another program is invalid.
    keep_unreadable : bool
        Make a file that cannot be read an invalid run (tonight's recording);
        False raises instead (a file in an archive may be no recording at all).

    Returns
    -------
    recording : Recording or None
    result : RunResult or None
    reason : str or None
        Why the run is invalid; None when it is valid.
    notes : tuple of str
        What the reading found missing (a cut file, a lost end of the run),
        one line each.
    """
    import warnings

    from imu_square.io.mcap import read_mcap
    from imu_square.pipeline.squareness import analyze

    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            recording = read_mcap(path)
    except ImuSquareError as exc:
        if not keep_unreadable:
            raise
        return None, None, _about_the_run(exc, path), ()
    notes = tuple(_about_the_run(w.message, path) for w in caught)
    _check_belongs(config, path, recording)
    recorded = recording.program
    if recorded is not None and recorded.n_feeds > 1:
        feeds = ", ".join(f"{v / MM_PER_MIN:g}" for v in recorded.feeds)
        return (
            recording,
            None,
            f"the recording runs {recorded.n_feeds} feeds ({feeds} mm/min): the monitor judges a "
            "one-feed test (analyse it with 'imu-square analyze --separate-gravity')",
            notes,
        )
    if program is not None and recording.program is not None and recording.program != program:
        return recording, None, program_mismatch(recording.program, program), notes
    try:
        with step("the analysis", AnalysisError):
            result = analyze(recording, config.analysis.options(), program=program)
    except AnalysisError as exc:
        return recording, None, _about_the_run(exc, path), notes
    return recording, result, None, notes


# The producers whose recordings name the machine they were made on.
_NAMES_ITS_MACHINE = ("imu-square record", "imu-square import")


def _check_belongs(config, path, recording):
    """Refuse a recording of another machine, or one whose time is no date: neither has a
    place in this machine's history (its nights are judged in recording-time order).

    The machine is that of a recording a recorder made or an import named; the
    simulator's recordings carry their model machine's name there instead."""
    recorded_on = recording.machine_id
    made_for = recording.metadata.get("producer") in _NAMES_ITS_MACHINE
    if made_for and recorded_on not in ("", config.machine_id):
        raise RecordingError(
            f"{path}: recorded on machine {recorded_on!r}, not this monitor's {config.machine_id!r}"
        )
    if not is_date(recording.time_ns[0]):
        raise RecordingError(
            f"{path}: its time ({int(recording.time_ns[0]) / 1e9:.3f} s since 1970) is no date: "
            f"a logger's clock since power-on; import it again with --start-time"
        )


def _about_the_run(message, path):
    """One line about a recording, without its path: the night's row names the file."""
    return first_line(message).removeprefix(f"{path}: ")


def recording_row(config, path, program=None, sha256=None, keep_unreadable=True):
    """A recording read, analysed and made into its history rows, valid or invalid.

    A valid run's diagnostics are fitted too (the monitor file's
    ``[diagnostics]``); their fit never makes the run invalid.

    Parameters
    ----------
    config : MonitorConfig
        The monitor file.
    path : str or Path
        The recording.
    program : TestProgram, optional
        The program the monitor expects.
    sha256 : str, optional
        The file's SHA-256, when the caller has it already.
    keep_unreadable : bool
        See :func:`analyse_recording`.

    Returns
    -------
    row : RunRow
    result : RunResult or None
        The analysis; None for an invalid run.
    diagnostics : DiagnosticFitRow or None
        The night's diagnostics, their run left for the store
        (:func:`store_run`); None for an invalid run or without a diagnostic set.
    """
    from imu_square.monitor.diagnostics.fit import diagnose_recording

    recording, result, reason, notes = analyse_recording(config, path, program, keep_unreadable)
    row = run_row(config, path, recording, result, reason, sha256, notes)
    diagnostics = None
    if result is not None:
        diagnostics = diagnose_recording(config.diagnostics, recording, program, config.analysis)
    return row, result, diagnostics


def store_run(history, row, diagnostics=None):
    """Store a run and its diagnostics, in one transaction.

    Parameters
    ----------
    history : History
        The open history.
    row : RunRow
        The run.
    diagnostics : DiagnosticFitRow or None
        Its diagnostic fit (its ``run_id`` is set here).

    Returns
    -------
    run_id : int
        The run's row.
    inserted : bool
        Whether the run or its diagnostics were new.
    """
    with history.transaction():
        run_id, inserted = history.add_run(row)
        if diagnostics is not None:
            inserted |= history.add_diagnostic_fit(replace(diagnostics, run_id=run_id))[1]
    return run_id, inserted


def program_mismatch(recorded, expected):
    """Why a recording of another circle test is not the monitor's: both named, one line."""
    return (
        f"the recording's program differs from the monitor's: {recorded.describe()} ran, "
        f"the monitor's is {expected.describe()}"
    )


def stored_design(history, baseline_row, settings):
    """The alarm design of a baseline, computed once and kept in the history."""
    from imu_square.monitor.stats.alarms import AlarmDesign

    if baseline_row is None:
        return None
    if baseline_row.alarm_design:
        return AlarmDesign.from_json_dict(baseline_row.alarm_design)
    runs = [history.run(i) for i in baseline_row.run_ids]
    with step("designing the alarm charts", MonitorError):
        design = design_for(
            baseline_row.eps_c_rad, baseline_row.u_squareness_mean_rad, runs, settings
        )
    history.set_alarm_design(baseline_row.id, design.to_json_dict())
    return design


def judge_history(config, history):
    """A machine's whole history judged against its current baseline.

    Parameters
    ----------
    config : MonitorConfig
        The monitor file (machine id, alarm settings).
    history : History
        The open history.

    Returns
    -------
    Assessment
    """
    machine = config.machine_id
    settings = settings_hash(analysis_settings(config))
    baseline_row = history.current_baseline(machine)
    if baseline_row is not None and baseline_row.settings_hash != settings:
        if not baseline_row.stale:
            # Its runs were analysed otherwise: a change against it would mix the two.
            baseline_row = replace(
                baseline_row,
                stale=True,
                stale_reason="the analysis settings changed since the baseline was set: set a "
                "new baseline, or replay its recordings ('imu-square replay')",
                stale_at_ns=baseline_row.last_run_at_ns,
            )
    design = stored_design(history, baseline_row, config.alarms)
    anchors = () if baseline_row is None else tuple(history.anchors(baseline_row.id))
    current = None if baseline_row is None else baseline_row.id
    earlier = {e.run_id: e for e in history.evaluations(machine) if e.baseline_id != current}
    runs = history.runs(machine, settings_hash=settings)
    assessment = judge_runs(runs, baseline_row, design, anchors, earlier)
    # a night the verdict does not judge (a warming sensor, ...) charts no diagnostic either
    judged = [n.run for n in assessment.nights if n.state != "invalid"]
    trends = judge_diagnostics(history, judged, baseline_row, config.diagnostics, config.alarms)
    return replace(
        assessment, earlier=_earlier_periods(config, history, baseline_row), diagnostics=trends
    )


def _earlier_periods(config, history, current):
    """Each earlier baseline's period judged against it, as it was then (oldest first), its
    diagnostics against their baselines of its nights."""
    rows = [b for b in history.baselines(config.machine_id) if current and b.id < current.id]
    if not rows:
        return ()
    periods = []
    for row, following in zip(rows, [*rows[1:], current], strict=True):
        runs = history.runs(
            config.machine_id,
            since=row.first_run_at_ns,
            until=following.first_run_at_ns,
            settings_hash=row.settings_hash,
        )
        design = stored_design(history, row, config.alarms)
        period = judge_runs(runs, row, design, tuple(history.anchors(row.id)))
        judged = [n.run for n in period.nights if n.state != "invalid"]
        trends = judge_diagnostics(history, judged, row, config.diagnostics, config.alarms)
        periods.append(replace(period, diagnostics=trends))
    return tuple(periods)


def judge_recording(config, history, path, program=None, alert=False, made=None):
    """Analyse, store and judge one night's recording.

    The run, its verdict and, with ``alert``, the night's alert for each sink
    are stored in one transaction: the night is in the history with its
    pending alerts, or not at all. Send them afterwards
    (:func:`~imu_square.monitor.alerts.send.deliver_alerts`).

    Parameters
    ----------
    config : MonitorConfig
        The monitor file.
    history : History
        The open history.
    path : str or Path
        The night's recording.
    program : TestProgram, optional
        The program the monitor expects.
    alert : bool
        Keep the night's alert in the outbox (a seeded past night has none).
    made : tuple, optional
        ``(row, result, diagnostics)`` of :func:`recording_row` for this
        recording, made already (elsewhere, in parallel); the recording is
        not read again.

    Returns
    -------
    NightOutcome
    """
    row, result, diagnostics = made or recording_row(config, path, program)
    with history.transaction():
        run_id, inserted = store_run(history, row, diagnostics)
        assessment = judge_history(config, history)
        baseline_row = assessment.baseline_row
        night = assessment.night_of(run_id)
        if night.state == "stale_baseline" and baseline_row is not None and not baseline_row.stale:
            history.mark_baseline_stale(
                baseline_row.id, night.reason, at_ns=night.run.recorded_at_ns
            )
        line = verdict(assessment, night)
        # read back when a later baseline makes this night one "of its time"
        store_verdict(history, baseline_row, night, verdict=line, reason=night.reason)
        record = night_record(assessment, night, line)
        sent = None
        if alert:
            sent = queue_alert(
                config.alerts,
                history,
                record,
                machine_id=config.machine_id,
                state=record["machine_state"],
                verdict=line,
            )
    return NightOutcome(run_id, inserted, night.state, line, record, assessment, result, sent)


def keep_for_later(out, path):
    """Note a night's recording that the history could not take, for the next run.

    Parameters
    ----------
    out : Path
        The monitor's data folder.
    path : Path
        The recording, kept on disk.
    """
    with open(Path(out) / KEPT_NIGHTS, "a", encoding="utf-8") as kept:
        kept.write(f"{Path(path).resolve()}\n")


def store_kept_nights(config, history, out, program=None):
    """Store, oldest first, the nights an earlier run kept for later; forget them once stored.

    A kept recording that is gone or refused is logged and forgotten; a
    history error stops the round and keeps the rest for the next run.

    Parameters
    ----------
    config : MonitorConfig
        The monitor file.
    history : History
        The open history.
    out : Path
        The monitor's data folder.
    program : TestProgram, optional
        The program the monitor expects.

    Returns
    -------
    list of NightOutcome
        The nights stored now, their alerts pending in the outbox.
    """
    listed = Path(out) / KEPT_NIGHTS
    if not listed.exists():
        return []
    waiting = [p for p in dict.fromkeys(listed.read_text(encoding="utf-8").split("\n")) if p]
    stored = []
    try:
        while waiting:
            path = Path(waiting[0])
            try:
                stored.append(judge_recording(config, history, path, program, alert=True))
            except HistoryError:
                raise
            except (OSError, ImuSquareError) as exc:
                logger.warning("kept night %s is not stored: %s", path, first_line(exc))
            waiting.pop(0)
    finally:
        if waiting:
            listed.write_text("".join(f"{p}\n" for p in waiting), encoding="utf-8")
        else:
            listed.unlink()
    return stored


def store_verdict(history, baseline_row, night, **notes):
    """Store a night's verdict against the baseline it was judged by.

    Parameters
    ----------
    history : History
        The open history.
    baseline_row : BaselineRow or None
        The baseline.
    night : Night
        The judged night.
    **notes
        Kept with the chart's statistics.
    """
    statistics = ({} if night.chart is None else night.chart.to_json_dict()) | notes
    judged = baseline_row is not None and night.state != "no_baseline"
    history.add_evaluation(
        EvaluationRow(
            run_id=night.run.id,
            baseline_id=baseline_row.id if judged else None,
            state=night.state,
            change_rad=_finite(night.change_rad),
            u_change_rad=_finite(night.u_change_rad),
            statistics=statistics,
        )
    )


def night_record(assessment, night, line):
    """The machine-readable record of a night (``nightly --json``, alerts).

    Parameters
    ----------
    assessment : Assessment
        The machine's assessment.
    night : Night
        The night.
    line : str
        Its verdict.

    Returns
    -------
    dict
        ``state`` (the night's), ``machine_state`` (``alarm`` while an alarm
        stands, else the night's) and ``alarm_since``, ``verdict``,
        ``change_urad``, ``u_change_urad``, the run's identity and analysis,
        the baseline and, when anchored, the absolute machine squareness;
        ``diagnostics``, each diagnostic's value, change and alarm state that
        night (:func:`~imu_square.monitor.diagnostics.trend.night_diagnostics`),
        and ``diagnostic_alarms``, those in alarm.
    """
    run = night.run
    base = assessment.baseline_row
    record = {
        "machine_id": run.machine_id,
        "state": night.state,
        "machine_state": machine_state(assessment, night),
        "alarm_since": None
        if assessment.alarm_since_ns is None
        else iso(assessment.alarm_since_ns),
        "verdict": line,
        "change_urad": _urad(night.change_rad),
        "u_change_urad": _urad(night.u_change_rad),
        "run_id": run.id,
        "recording": run.recording_path,
        "recording_sha256": run.recording_sha256,
        "recorded_at": iso(run.recorded_at_ns),
        "valid": run.valid,
        "invalid_reason": run.invalid_reason,
        "reason": night.reason,
        "drift": json_safe(night.drift or None, urad=True),
        "drift_corrected": night.drift_corrected,
        "squareness_urad": _urad(run.squareness_rad),
        "u_squareness_urad": _urad(run.u_squareness_rad),
        "eps_c_deg": None if run.eps_c_rad is None else math.degrees(run.eps_c_rad),
        "warnings": list(run.warnings),
        "baseline": None
        if base is None
        else {
            "id": base.id,
            "squareness_urad": base.squareness_mean_rad / URAD,
            "u_squareness_urad": base.u_squareness_mean_rad / URAD,
            "eps_c_deg": math.degrees(base.eps_c_rad),
            "created_at": iso(base.created_at_ns),
            "stale": base.stale or night.state == "stale_baseline",
        },
        "chart": None if night.chart is None else night.chart.to_json_dict(),
    }
    record["diagnostics"] = night_diagnostics(assessment.diagnostics, run.id)
    record["diagnostic_alarms"] = [
        name for name, d in record["diagnostics"].items() if d["state"] == "alarm"
    ]
    anchored = machine_squareness(assessment, night)
    if anchored is not None:
        record["machine_squareness_urad"] = anchored[0] / URAD
        record["u_machine_squareness_urad"] = _urad(anchored[1])
    return record


def _finite(x):
    return float(x) if x is not None and math.isfinite(x) else None


def _urad(x):
    return None if x is None or not math.isfinite(x) else x / URAD
