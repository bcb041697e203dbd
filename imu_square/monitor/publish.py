"""After a night is judged: the trend chart, the report, the metrics file and the alerts.

Called once the night is in the history, with its alerts pending in the
outbox, so that nothing here can lose the run: an alert that is not sent
stays pending (:mod:`.alerts.send`), and a figure that cannot be drawn is
logged, not raised.
"""

import math
from dataclasses import dataclass
from pathlib import Path

from imu_square.errors import ImuSquareError, ImuSquareWarning
from imu_square.log import logger
from imu_square.monitor.history.encoding import datetime_from_ns


@dataclass(frozen=True)
class NightFiles:
    """What a night wrote besides the history.

    Attributes
    ----------
    trend_png, report_html : Path or None
        The trend chart and the report; None when they could not be written.
    diagnostics_png : Path or None
        The diagnostics' trend chart; None without diagnostics, or when it
        could not be written.
    metrics : Path or None
        The Prometheus text file, when configured.
    alerts : AlertReport or None
        What each sink did with the night's alert.
    """

    trend_png: Path | None
    report_html: Path | None
    metrics: Path | None
    alerts: object
    diagnostics_png: Path | None = None


def ensure_folder(folder, what, make=True):
    """Make ``folder`` if needed and check a file can be written in it, before any work.

    Only the folder itself is made, never its parents: a path under a share
    that is not mounted must fail, not fill the local disk.

    Parameters
    ----------
    folder : str or Path
        The folder.
    what : str
        What goes there, for the message (e.g. ``"data"``).
    make : bool
        Make a missing folder; False only checks that it could be made
        (``nightly --check``).

    Returns
    -------
    Path

    Raises
    ------
    OutputError
        One line naming the folder and why it cannot be used.
    """
    from imu_square.errors import OutputError
    from imu_square.io.output import check_output_path

    folder = Path(folder)
    if not folder.is_dir():
        if not folder.parent.is_dir():
            why = "is not a folder" if folder.parent.exists() else "does not exist (not mounted?)"
            raise OutputError(f"{folder}: cannot create the {what} folder: {folder.parent} {why}")
        if not make:
            check_output_path(folder.parent / ".imu-square-probe", overwrite=True)
            return folder
        try:
            folder.mkdir()
        except OSError as exc:
            raise OutputError(
                f"{folder}: cannot create the {what} folder: {exc.strerror or exc}"
            ) from None
    check_output_path(folder / ".imu-square-probe", overwrite=True)
    return folder


def last_valid_result(assessment, options):
    """The analysis of the latest valid run whose recording is still on disk, and its path.

    Parameters
    ----------
    assessment : Assessment
        The machine's assessment.
    options : AnalysisOptions
        The analysis settings.

    Returns
    -------
    result : RunResult or None
    path : str
    """
    import warnings

    from imu_square.io.mcap import read_mcap
    from imu_square.pipeline.squareness import analyze

    for night in reversed(assessment.nights):
        run = night.run
        if run.valid and Path(run.recording_path).is_file():
            try:
                with warnings.catch_warnings():  # said when the night was stored, with it
                    warnings.simplefilter("ignore", ImuSquareWarning)
                    return analyze(read_mcap(run.recording_path), options), run.recording_path
            except ImuSquareError as exc:
                logger.warning("%s: cannot redraw the last run: %s", run.recording_path, exc)
    return None, ""


def metrics_snapshot(assessment):
    """The metrics of a machine's assessment (:class:`~.metrics.MetricsSnapshot`)."""
    from imu_square.monitor.report.metrics import MetricsSnapshot

    nights = assessment.nights
    latest = nights[-1] if nights else None
    valid = [n for n in nights if n.run.valid]
    judged = [n for n in valid if math.isfinite(n.change_rad)]
    last_valid = valid[-1] if valid else None

    def when(night):
        return None if night is None else datetime_from_ns(night.run.recorded_at_ns)

    return MetricsSnapshot(
        machine_id=assessment.machine_id,
        state=assessment.state,
        runs=len(nights),
        invalid_runs=len(nights) - len(valid),
        change_rad=judged[-1].change_rad if judged else None,
        u_change_rad=judged[-1].u_change_rad if judged else None,
        eps_c_rad=last_valid.run.eps_c_rad if last_valid else None,
        u_eps_c_rad=last_valid.run.u_eps_c_rad if last_valid else None,
        last_run_at=when(latest),
        last_valid_run_at=when(last_valid),
    )


def write_night_outputs(config, history, outcome, out_dir):
    """Draw the trend charts and the report, write the metrics, send the alerts.

    Parameters
    ----------
    config : MonitorConfig
        The monitor file.
    history : History
        The open history, holding the night (outside any transaction).
    outcome : NightOutcome
        The judged night; its alert, if any, is sent with those pending.
    out_dir : Path
        Folder for the chart and the report.

    Returns
    -------
    NightFiles
    """
    from imu_square.monitor.report.diagnostics_figure import plot_diagnostics
    from imu_square.monitor.report.figures import plot_trend
    from imu_square.monitor.report.html import render_report, write_report

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    assessment = outcome.assessment
    trend = _chart(plot_trend, assessment, out_dir / f"{config.machine_id}-trend.png", "trend")
    diagnostics = None
    if assessment.diagnostics:
        path = out_dir / f"{config.machine_id}-diagnostics.png"
        diagnostics = _chart(plot_diagnostics, assessment, path, "diagnostics")
    report = out_dir / f"{config.machine_id}-report.html"
    try:
        last, title = last_valid_result(assessment, config.analysis.options())
        write_report(report, render_report(assessment, last, title))
    except (OSError, ValueError, ImuSquareError) as exc:
        logger.warning("%s: report not written: %s", report, exc)
        report = None
    metrics = None
    if config.metrics is not None and config.metrics.textfile is not None:
        from imu_square.monitor.report.metrics import write_metrics

        try:
            metrics = write_metrics(config.metrics.textfile, metrics_snapshot(assessment))
        except ImuSquareError as exc:
            logger.warning("%s", exc)
    alerts = None
    if outcome.alert is not None:
        from imu_square.monitor.alerts.send import deliver_alerts

        try:
            alerts = deliver_alerts(config.alerts, history, config.machine_id, outcome.alert)
        except ImuSquareError as exc:
            logger.error("alerts not sent now (%s): they stay pending in the history", exc)
    return NightFiles(trend, report, metrics, alerts, diagnostics)


def _chart(plot, assessment, path, what):
    """``path`` once ``plot`` has drawn it; None, said, when it could not."""
    try:
        plot(assessment, path)
    except (OSError, ValueError) as exc:
        logger.warning("%s: %s chart not written: %s", path, what, exc)
        return None
    return path
