"""The diagnostics' trend chart: one panel per effect, every night's value with its uncertainty.

Each panel shows an effect's diagnostics (X and Y together) in their own
unit: every valid night's value with its standard uncertainty and, as an x
on the panel's bottom edge, the judged nights it has no value for (its fit
gave none, or the night has no fit under these settings). Every baseline's
period is drawn against that baseline, as the squareness's trend chart draws
it (:mod:`.figures`): where its runs were and where they begin, the
diagnostic's baseline value with its band (``±u`` of the baseline), the alarm
limits of a diagnostic that has an alarm (its baseline ``± L u`` of each
night, ``L`` the Shewhart limit), and the nights its charts were past their
warning or alarm limits; so an alarm that fired before the current baseline
stays in view.
"""

import math

from imu_square.monitor.history.encoding import datetime_from_ns
from imu_square.monitor.report.figures import (
    baseline_runs,
    in_period,
    mark_baseline,
    once,
    periods,
)

_COLOURS = ("tab:blue", "tab:green", "tab:purple")


def plot_diagnostics(assessment, path, title=""):
    """Write the diagnostics' trend chart of a machine's assessment as a PNG.

    Parameters
    ----------
    assessment : Assessment
        The machine's history judged, with its diagnostics
        (:attr:`~imu_square.monitor.verdict.Assessment.diagnostics`) and its
        earlier baselines' periods with theirs
        (:attr:`~imu_square.monitor.verdict.Assessment.earlier`).
    path : str or Path
        PNG file to write.
    title : str
        Title; the machine id if empty.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.dates as mdates
    import matplotlib.pyplot as plt

    by_effect = {}
    for trend in assessment.diagnostics:
        by_effect.setdefault(trend.diagnostic.effect, []).append(trend.diagnostic)
    n = max(len(by_effect), 1)
    fig, axes = plt.subplots(
        n, 1, figsize=(11, 1.0 + 2.3 * n), sharex=True, squeeze=False, constrained_layout=True
    )
    axes = axes[:, 0]
    labelled = set()
    for ax, (effect, diagnostics) in zip(axes, by_effect.items(), strict=False):
        for period in periods(assessment):
            mark_baseline((ax,), period.baseline_row, labelled)
        for d, colour in zip(diagnostics, _COLOURS, strict=False):
            _draw(ax, _period_trends(assessment, d.name), colour, labelled)
            _draw_missing(ax, assessment, d.name, colour, labelled)
        ax.set_title(effect.replace("_", " "), fontsize=9, loc="left")
        ax.set_ylabel(f"[{diagnostics[0].unit}]")
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7, ncol=4, loc="upper left")
    if not by_effect:
        axes[0].text(0.5, 0.5, "no diagnostics", ha="center", va="center")
    axes[0].figure.suptitle(title or f"machine {assessment.machine_id}: diagnostics")
    axes[-1].xaxis.set_major_formatter(mdates.ConciseDateFormatter(mdates.AutoDateLocator()))
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _period_trends(assessment, name):
    """A diagnostic's trend in every baseline's period: ``(period, trend)``, oldest first."""
    return [
        (period, trend)
        for period in periods(assessment)
        for trend in period.diagnostics
        if trend.diagnostic.name == name
    ]


def _when(night):
    return datetime_from_ns(night.run.recorded_at_ns)


def _draw(ax, period_trends, colour, labelled):
    """One diagnostic: its nights, then each period's band, limits and alarm nights."""
    d = period_trends[-1][1].diagnostic
    by_run = {}  # each night once, from the latest period that has it
    for _, trend in period_trends:
        by_run.update({n.run.id: n for n in trend.nights if n.run.recorded_at_ns is not None})
    nights = sorted(by_run.values(), key=lambda n: n.run.recorded_at_ns)
    valued = [n for n in nights if math.isfinite(n.value)]
    if valued:
        ax.errorbar(
            [_when(n) for n in valued],
            [n.value / d.scale for n in valued],
            yerr=[n.u_value / d.scale for n in valued],
            fmt="o",
            ms=3,
            capsize=2,
            lw=0.8,
            color=colour,
            label=once(labelled, d.name),
        )
    for period, trend in period_trends:
        _draw_period(ax, period, trend, colour, labelled)


def _draw_missing(ax, assessment, name, colour, labelled):
    """An x on the panel's bottom edge for each judged night a diagnostic has no value for:
    missing from its fit, or not fitted under these settings (a night the verdict
    does not judge charts no diagnostic, :func:`~imu_square.monitor.night.judge_history`).

    The x sits in axes coordinates (a blended transform: the night's time, the
    panel's bottom), so it never lands on a value whatever the limits become.
    """
    valued = {
        n.run.id
        for _, trend in _period_trends(assessment, name)
        for n in trend.nights
        if math.isfinite(n.value)
    }
    missing = [
        n
        for n in assessment.nights
        if n.state != "invalid" and n.run.recorded_at_ns is not None and n.run.id not in valued
    ]
    if missing:
        ax.plot(
            [_when(n) for n in missing],
            [0.0] * len(missing),
            "x",
            color=colour,
            transform=ax.get_xaxis_transform(),
            clip_on=False,
            label=once(labelled, f"{name}: no value"),
        )


def _draw_period(ax, period, trend, colour, labelled):
    """A diagnostic in one baseline's period: its baseline band, its limits, its alarm nights."""
    d, base = trend.diagnostic, trend.baseline
    valued = [n for n in in_period(period, trend.nights) if math.isfinite(n.value)]
    runs = baseline_runs(period.baseline_row)
    if base is not None and runs is not None:
        span = [runs[0], max([runs[1], *map(_when, valued)])]
        v, u = base.value / d.scale, base.u_value / d.scale
        ax.hlines(v, *span, colors=colour, lw=0.8, ls=":")
        ax.fill_between(span, v - u, v + u, color=colour, alpha=0.15)
    charted = [n for n in valued if n.chart is not None]
    if trend.design is not None and charted:
        limit = trend.design.shewhart.limit
        for sign in (1, -1):
            ax.step(
                [_when(n) for n in charted],
                [
                    (base.value + sign * limit * math.hypot(n.u_value, base.between)) / d.scale
                    for n in charted
                ],
                where="mid",
                color=colour,
                lw=0.7,
                ls="--",
                label=once(labelled, f"{d.name} alarm limit") if sign == 1 else None,
            )
    for state, marker, face in (("warning", "D", "tab:orange"), ("alarm", "s", "tab:red")):
        sel = [n for n in charted if n.state == state]
        if sel:
            ax.plot(
                [_when(n) for n in sel],
                [n.value / d.scale for n in sel],
                marker,
                mfc="none",
                mec=face,
                ms=8,
                label=once(labelled, f"{d.name} {state}"),
            )
