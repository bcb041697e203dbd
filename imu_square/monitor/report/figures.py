"""The monitor's figures: the trend chart and the sensor's state over time.

The trend chart shows every night's change since the baseline of its time
with its standard uncertainty, the alarm design's Shewhart limits (``+-L u``
of each night), each baseline's own band, runs and start, anchors, remounts
and invalid runs, and below it the EWMA and CUSUM statistics with their
limits, every baseline's period with its own, so a reader can see why a night
was judged as it was, before a repair as after it.
"""

import math

import numpy as np

from imu_square.monitor.history.encoding import datetime_from_ns
from imu_square.units import URAD

_STATE_STYLE = {
    "ok": ("tab:blue", "o"),
    "warning": ("tab:orange", "D"),
    "alarm": ("tab:red", "s"),
    "stale_baseline": ("tab:purple", "v"),
}


def _legend(ax, ncol=1):
    """A legend, when the axes hold something labelled (matplotlib warns otherwise)."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7, ncol=ncol, loc="upper left")


def _dates(nights):
    return [datetime_from_ns(n.run.recorded_at_ns) for n in nights]


def plot_trend(assessment, path, title=""):
    """Write the trend chart of a machine's assessment as a PNG.

    Every baseline's period is drawn against that baseline, with its own
    limits and chart statistics, so an earlier alarm's climb stays in view; a
    dotted line marks where each baseline's runs begin.

    Parameters
    ----------
    assessment : Assessment
        The machine's history judged against its current baseline (and its
        earlier baselines' periods, :attr:`Assessment.earlier`).
    path : str or Path
        PNG file to write.
    title : str
        Title; the machine id if empty.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.dates as mdates
    import matplotlib.pyplot as plt

    fig, (top, bottom) = plt.subplots(
        2, 1, figsize=(11, 7.5), sharex=True, height_ratios=(3, 2), constrained_layout=True
    )
    top.axhline(0.0, color="black", lw=0.8)
    labelled = set()
    for period in periods(assessment):
        _draw_period(top, bottom, period, labelled)
    nights = [n for n in assessment.nights if n.run.recorded_at_ns is not None]
    invalid = [n for n in nights if n.state == "invalid"]
    if invalid:
        y0 = top.get_ylim()[0]
        top.plot(_dates(invalid), [y0] * len(invalid), "x", color="grey", label="invalid run")
    stale = [n for n in nights if n.state == "stale_baseline"]
    if stale:
        top.axvline(_dates(stale[:1])[0], color="tab:purple", ls=":", label="sensor remounted")
    if math.isfinite(assessment.anchor_rad):
        offset = assessment.anchor_rad / URAD
        right = top.secondary_yaxis("right", functions=(lambda y: y + offset, lambda y: y - offset))
        right.set_ylabel("machine squareness (anchored) [µm/m]")
    top.set_ylabel("change since the baseline of its time [µm/m]")
    top.set_title(title or f"machine {assessment.machine_id}: squareness change")
    _legend(top, ncol=3)
    top.grid(alpha=0.3)
    bottom.set_ylabel("chart statistic [z units]")
    bottom.set_title("EWMA and CUSUM on z = change / its uncertainty")
    _legend(bottom, ncol=4)
    bottom.grid(alpha=0.3)
    bottom.xaxis.set_major_formatter(mdates.ConciseDateFormatter(mdates.AutoDateLocator()))
    fig.savefig(path, dpi=100)
    plt.close(fig)


def periods(assessment):
    """Every baseline's period of an assessment, oldest first, the current one last.

    Parameters
    ----------
    assessment : Assessment
        The machine's history judged (:attr:`Assessment.earlier` its earlier periods).

    Returns
    -------
    tuple of Assessment
        Each judged against its own baseline.
    """
    return (*assessment.earlier, assessment)


def in_period(period, nights):
    """The nights of a baseline's period: recorded, and not before its baseline's first run."""
    base = period.baseline_row
    start = base.first_run_at_ns if base is not None else None
    return [
        n
        for n in nights
        if n.run.recorded_at_ns is not None and (start is None or n.run.recorded_at_ns >= start)
    ]


def baseline_runs(base):
    """When a baseline's runs were: its first and last as datetimes, or None.

    Parameters
    ----------
    base : BaselineRow or None
        The baseline.

    Returns
    -------
    tuple of datetime or None
        None without a baseline or its runs' times.
    """
    if base is None or not (base.first_run_at_ns and base.last_run_at_ns):
        return None
    return datetime_from_ns(base.first_run_at_ns), datetime_from_ns(base.last_run_at_ns)


def mark_baseline(axes, base, labelled):
    """Shade a baseline's runs and mark where they begin, on each of the axes.

    Parameters
    ----------
    axes : sequence of Axes
        Where to mark it.
    base : BaselineRow or None
        The baseline (nothing is marked without its runs' times).
    labelled : set of str
        The legend entries given already (:func:`once`).
    """
    runs = baseline_runs(base)
    if runs is None:
        return
    for ax in axes:
        ax.axvspan(*runs, color="tab:green", alpha=0.12, label=once(labelled, "baseline runs"))
        ax.axvline(runs[0], color="tab:green", ls=":", lw=1.0, label=once(labelled, "baseline set"))


def once(labelled, name):
    """A legend entry's label the first time, None after: each entry once, however many
    periods draw it."""
    if name in labelled:
        return None
    labelled.add(name)
    return name


def _draw_period(top, bottom, assessment, labelled):
    """One baseline's period: its band, its nights, its limits and its chart statistics."""

    def label(name):
        return once(labelled, name)

    base, design = assessment.baseline_row, assessment.design
    nights = in_period(assessment, assessment.nights)
    mark_baseline((top, bottom), base, labelled)
    marked = baseline_runs(base)
    if marked is not None:
        band = base.u_squareness_mean_rad / abs(math.cos(2 * base.eps_c_rad)) / URAD
        span = [marked[0], max([marked[1], *_dates(nights)])]
        top.fill_between(
            span, -band, band, color="tab:green", alpha=0.2, label=label("baseline ±u")
        )
    judged = [n for n in nights if math.isfinite(n.change_rad)]
    for state, (colour, marker) in _STATE_STYLE.items():
        sel = [n for n in judged if n.state == state]
        if sel:
            top.errorbar(
                _dates(sel),
                [n.change_rad / URAD for n in sel],
                yerr=[n.u_change_rad / URAD for n in sel],
                fmt=marker,
                color=colour,
                ms=4,
                capsize=2,
                lw=0.8,
                label=label(state),
            )
    latched = [n for n in judged if n.state == "alarm" and n.chart and n.chart.state != "alarm"]
    if latched:
        top.plot(
            _dates(latched),
            [n.change_rad / URAD for n in latched],
            "s",
            mfc="none",
            mec="tab:red",
            ms=9,
            label=label("alarm standing"),
        )
    charted = [n for n in judged if n.chart is not None]
    if design is None or not charted:
        return
    dates = _dates(charted)
    lim = np.array([design.shewhart.limit * n.chart.u_change_rad / URAD for n in charted])
    top.step(
        dates, lim, where="mid", color="tab:red", lw=0.8, ls="--", label=label("Shewhart limit")
    )
    top.step(dates, -lim, where="mid", color="tab:red", lw=0.8, ls="--")
    bottom.plot(dates, [n.chart.ewma for n in charted], "-", color="tab:cyan", label=label("EWMA"))
    bottom.plot(
        dates, [n.chart.cusum_pos for n in charted], "-", color="tab:brown", label=label("CUSUM +")
    )
    bottom.plot(
        dates, [-n.chart.cusum_neg for n in charted], "-", color="tab:olive", label=label("CUSUM −")
    )
    for value, colour, name in (
        (design.ewma.limit, "tab:cyan", "EWMA limit"),
        (design.cusum.limit, "tab:brown", "CUSUM limit"),
    ):
        bottom.hlines(
            [value, -value], dates[0], dates[-1], colors=colour, ls="--", lw=0.8, label=label(name)
        )


def plot_sensor(assessment, path):
    """Write eps_c and the sensor temperature over the nights as a PNG.

    Parameters
    ----------
    assessment : Assessment
        The machine's history.
    path : str or Path
        PNG file to write.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.dates as mdates
    import matplotlib.pyplot as plt

    valid = [n for n in assessment.nights if n.run.valid and n.run.recorded_at_ns is not None]
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(11, 5), sharex=True, constrained_layout=True)
    if valid:
        top.errorbar(
            _dates(valid),
            [math.degrees(n.run.eps_c_rad) for n in valid],
            yerr=[math.degrees(n.run.u_eps_c_rad) for n in valid],
            fmt="o",
            ms=3,
            capsize=2,
            color="tab:green",
        )
    base = assessment.baseline_row
    if base is not None:
        top.axhline(math.degrees(base.eps_c_rad), color="black", lw=0.8, label="baseline eps_c")
        _legend(top)
    top.set_ylabel("eps_c [deg]")
    top.set_title("sensor rotation about Z (a jump is a remount)")
    top.grid(alpha=0.3)
    temps = [n for n in valid if n.run.temperature_mean_c is not None]
    if temps:
        bottom.plot(_dates(temps), [n.run.temperature_mean_c for n in temps], "o-", ms=3)
        bottom.set_ylabel("sensor temperature [°C]")
        bottom.set_title("sensor temperature, mean over each run")
    else:
        up = [n for n in valid if n.run.time_since_power_on_s is not None]
        bottom.plot(_dates(up), [n.run.time_since_power_on_s / 60 for n in up], "o", ms=3)
        bottom.set_ylabel("sensor on for [min]")
        bottom.set_title("time since the sensor's power-on at each run (no temperature channel)")
    bottom.grid(alpha=0.3)
    bottom.xaxis.set_major_formatter(mdates.ConciseDateFormatter(mdates.AutoDateLocator()))
    fig.savefig(path, dpi=100)
    plt.close(fig)
