"""The diagnostics' trend chart: one panel per effect, every night's value with its uncertainty.

Each panel shows an effect's diagnostics (X and Y together) in their own
unit: every valid night's value with its standard uncertainty, the
diagnostic's baseline value with its band (``±u`` of the baseline), the
alarm limits of a diagnostic that has an alarm (its baseline ``± L u`` of
each night, ``L`` the Shewhart limit), the nights its charts were past their
warning or alarm limits, and the nights whose fit gave no value.
"""

import math

from imu_square.monitor.history.encoding import datetime_from_ns

_COLOURS = ("tab:blue", "tab:green", "tab:purple")


def plot_diagnostics(assessment, path, title=""):
    """Write the diagnostics' trend chart of a machine's assessment as a PNG.

    Parameters
    ----------
    assessment : Assessment
        The machine's history judged, with its diagnostics
        (:attr:`~imu_square.monitor.verdict.Assessment.diagnostics`).
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
        by_effect.setdefault(trend.diagnostic.effect, []).append(trend)
    n = max(len(by_effect), 1)
    fig, axes = plt.subplots(
        n, 1, figsize=(11, 1.0 + 2.3 * n), sharex=True, squeeze=False, constrained_layout=True
    )
    axes = axes[:, 0]
    for ax, (effect, trends) in zip(axes, by_effect.items(), strict=False):
        for trend, colour in zip(trends, _COLOURS, strict=False):
            _draw(ax, trend, colour)
        ax.set_title(effect.replace("_", " "), fontsize=9, loc="left")
        ax.set_ylabel(f"[{trends[0].diagnostic.unit}]")
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7, ncol=4, loc="upper left")
    if not by_effect:
        axes[0].text(0.5, 0.5, "no diagnostics", ha="center", va="center")
    axes[0].figure.suptitle(title or f"machine {assessment.machine_id}: diagnostics")
    axes[-1].xaxis.set_major_formatter(mdates.ConciseDateFormatter(mdates.AutoDateLocator()))
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _when(night):
    return datetime_from_ns(night.run.recorded_at_ns)


def _draw(ax, trend, colour):
    """One diagnostic: its nights, its baseline band, its limits and its alarm nights."""
    d = trend.diagnostic
    nights = [n for n in trend.nights if n.run.recorded_at_ns is not None]
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
            label=d.name,
        )
    base = trend.baseline
    if base is not None and valued:
        span = [_when(valued[0]), _when(valued[-1])]
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
                label=f"{d.name} alarm limit" if sign == 1 else None,
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
                label=f"{d.name} {state}",
            )
    missing = [n for n in nights if not math.isfinite(n.value)]
    if missing:
        low = ax.get_ylim()[0]
        ax.plot([_when(n) for n in missing], [low] * len(missing), "x", color="grey")
