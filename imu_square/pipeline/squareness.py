"""From a recording to the squareness: the whole pipeline, one call.

:func:`analyze` runs filter -> segment -> flip/average -> fit and returns a
frozen :class:`RunResult`:

- ``theta_y - theta_x`` of the flipped and averaged CCW and CW traces (paper,
  Eq. 4 [1]_), averaged over the two directions; this cancels the servo
  mismatch, which is half their difference (``docs/model.md``). It is the
  paper's measurand as defined, machine plus sensor: sensor axes rotated by
  ``eps_c`` see ``theta_y - theta_x = beta + (alpha +- m) cos(2 eps_c)``, so the
  servo mismatch is reported divided by ``cos(2 eps_c)`` (exact), and the
  monitor divides the *change* of ``theta_y - theta_x`` by it, in which the
  sensor's ``beta`` cancels;
- ``eps_c``, the sensor's rotation about Z (:mod:`imu_square.pipeline.rotation`;
  the paper's stage 2 is degenerate, see :mod:`imu_square.pipeline.sine_fit`; its
  value is kept as ``eps_c_stage2_rad``);
- uncertainties: type A from the per-cycle scatter (CCW cycle k paired with
  CW cycle k) with its Student's t coverage factor, a bootstrap over cycles,
  and the Cramér-Rao bound for the noise at the circle frequency
  (:mod:`imu_square.pipeline.noise_floor`);
- a bound on what the servos' amplitude mismatch adds through ``eps_c``
  (:mod:`imu_square.pipeline.servo`);
- quality flags, and refusal (:class:`AnalysisError`) when the data cannot give
  a trustworthy number.

References
----------
.. [1] K. Szipka, A. Archenti, G. W. Vogl, M. A. Donmez, "Identification of
   machine tool squareness errors via inertial measurements", CIRP Annals 68
   (2019).
"""

import math

import numpy as np

from imu_square.blas import one_blas_thread
from imu_square.errors import AnalysisError
from imu_square.log import logger
from imu_square.pipeline import quality as q
from imu_square.pipeline.align import bad_intervals, cycle_traces, interpolation_gain
from imu_square.pipeline.circle_speed import circle_speed
from imu_square.pipeline.filter import filter_recording, passband_gain
from imu_square.pipeline.noise_floor import noise_floor
from imu_square.pipeline.options import AnalysisOptions
from imu_square.pipeline.per_cycle import fit_cycles
from imu_square.pipeline.result import DirectionResult, RunResult
from imu_square.pipeline.rotation import circular_mean, eps_c_uncertainty, estimate_eps_c
from imu_square.pipeline.segment import block_events, segment
from imu_square.pipeline.servo import servo_amplitude_bound
from imu_square.pipeline.sine_fit import fit_mean_traces
from imu_square.pipeline.stage2 import fit_cross_terms
from imu_square.pipeline.uncertainty import coverage_factor, type_a

__all__ = ["AnalysisOptions", "DirectionResult", "RunResult", "analyze"]


def filter_and_segment(recording, program, cutoff_hz, order):
    """Low-pass a recording (short gaps bridged) and find the program's blocks in it.

    Parameters
    ----------
    recording : Recording
        The test as recorded.
    program : TestProgram
        The program it ran.
    cutoff_hz : float or None
        Low-pass cutoff; None for 8 pi x the circle frequency. [Hz]
    order : int
        Low-pass order.

    Returns
    -------
    data : FilteredRecording
    seg : Segmentation
    """
    data = filter_recording(recording, cutoff_hz, order, program.frequency_hz)
    seg = segment(
        data.t_s,
        data.xy,
        program,
        block_events(recording),
        data.margin_s,
        gaps_s=data.long_gap_spans_s,
        short_gaps_s=data.short_gap_spans_s,
        reach_s=data.reach_s,
    )
    return data, seg


def trace_cycles(data, seg, grid_points):
    """The usable whole cycles on the position-angle grid, clipping and gaps left out.

    Parameters
    ----------
    data : FilteredRecording
        From :func:`filter_and_segment` (its gaps and clipped samples).
    seg : Segmentation
        From :func:`filter_and_segment`.
    grid_points : int
        Points of the phi grid per cycle.

    Returns
    -------
    CycleTraces
    """
    return cycle_traces(
        data.t_s,
        data.xy,
        seg,
        bad_intervals(data.gap_spans_s, data.clipped_s),
        data.margin_s,
        grid_points,
        missing_s=data.bridged_spans_s,
        onset_margin_s=data.onset_margin_s,
    )


@one_blas_thread()  # many small solves: BLAS threads only cost (imu_square.blas)
def analyze(recording, options=None, program=None):
    """Squareness, sensor rotation and servo mismatch of one recording.

    Parameters
    ----------
    recording : Recording
        The test as recorded; all its blocks (every run) are analysed together.
    options : AnalysisOptions, optional
        The paper's choices if None.
    program : TestProgram, optional
        Overrides ``recording.program``.

    Returns
    -------
    RunResult

    Raises
    ------
    AnalysisError
        No program; no circle matching the program; a block turning the wrong
        way; a period far from the program's that the amplitude does not
        confirm (a controller that ran the arcs slower is taken at its measured
        speed, with a warning: :mod:`imu_square.pipeline.circle_speed`); an
        amplitude far from the circle's; too few usable cycles. The message
        does not name the recording: the caller does.
    """
    opts = options or AnalysisOptions()
    prog = _program_of(recording, program)
    data, seg = filter_and_segment(recording, prog, opts.cutoff_hz, opts.order)
    cyc = trace_cycles(data, seg, opts.grid_points)
    q.check_cycles(cyc.ccw.n, cyc.cw.n, prog, opts.min_cycles, cyc.dropped)

    norm, irls = opts.robust_norm(), opts.irls()
    f0, fs = 1 / seg.period_s, data.sample_rate_hz
    gain = passband_gain(f0, data.cutoff_hz, opts.order, fs) * interpolation_gain(f0, fs)
    mean = fit_mean_traces(cyc, gain, norm, **irls)
    speed = circle_speed(seg, mean.amplitude_m_s2, prog)
    eps_c = estimate_eps_c(mean)
    cos2 = math.cos(2 * eps_c)
    cycles = fit_cycles(cyc, mean, cos2, seg.period_s, norm, irls, opts.bootstrap_n, opts.seed)
    if cycles.n_pairs < 2:
        raise AnalysisError(
            f"too few CCW/CW cycle pairs for an uncertainty: {cycles.n_pairs} "
            f"(cycles used: {cyc.ccw.n} CCW, {cyc.cw.n} CW)"
        )
    u_sq = type_a(cycles.squareness_rad)
    k = coverage_factor(cycles.n_pairs - 1, opts.coverage_probability)
    floor = noise_floor(data, seg, cyc, mean, recording.sensor)
    outliers = q.outlier_fractions(mean)
    quality = q.quality_flags(
        recording,
        seg,
        cyc,
        data.clipped_s,
        speed.amplitude_ratio,
        outliers,
        u_sq,
        floor,
        data,
        speed_warning=speed.warning(prog),
    )
    for w in quality["warnings"]:
        logger.debug("quality: %s", w)

    sq_dir = mean.squareness_rad
    fit = mean.fit
    servo_rad = 0.5 * float(sq_dir[0] - sq_dir[1]) / cos2
    amplitude_over_circle = mean.amplitude_m_s2 / (seg.omega_rad_s**2 * prog.radius_m)
    return RunResult(
        squareness_rad=0.5 * float(sq_dir[0] + sq_dir[1]),
        u_squareness_rad=u_sq,
        u_squareness_dof=cycles.n_pairs - 1,
        u_squareness_bootstrap_rad=cycles.u_bootstrap_rad,
        crb_rad=floor.crb_rad,
        noise_density_m_s2_rthz=floor.noise_density_m_s2_rthz,
        noise_density_source=floor.source,
        theta_x_rad=circular_mean(fit.theta_x[0], fit.theta_x[1]),
        theta_y_rad=circular_mean(fit.theta_y[0], fit.theta_y[1]),
        eps_c_rad=eps_c,
        u_eps_c_rad=eps_c_uncertainty(cycles.eps_c_rad, seg),
        eps_c_stage2_rad=float(np.mean(fit_cross_terms(cyc.phi_grid, fit, norm, **irls).eps_c)),
        amp_x_m_s2=float(np.mean(mean.amp_x_m_s2)),
        amp_y_m_s2=float(np.mean(mean.amp_y_m_s2)),
        servo_mismatch_rad=servo_rad,
        u_servo_mismatch_rad=type_a(cycles.servo_mismatch_rad),
        ccw=_direction(mean, 0, cyc.ccw.n, outliers),
        cw=_direction(mean, 1, cyc.cw.n, outliers),
        per_cycle=_per_cycle(cycles, recording, data.t_s, seg.period_s),
        cycles_used={"ccw": int(cyc.ccw.n), "cw": int(cyc.cw.n)},
        omega_rad_s=seg.omega_rad_s,
        period_s=seg.period_s,
        quality=quality,
        traces=_traces(cyc.phi_grid, mean),
        options=opts,
        cutoff_hz=data.cutoff_hz,
        cutoff_source="circle" if opts.cutoff_hz is None else "options",
        noise_density_circle_m_s2_rthz=floor.circle_density_m_s2_rthz,
        flicker_corner_hz=floor.flicker_corner_hz,
        crb_white_rad=floor.crb_white_rad,
        coverage_factor=k,
        u_squareness_expanded_rad=k * u_sq,
        servo_amplitude_bias_bound_rad=servo_amplitude_bound(
            servo_rad, eps_c, amplitude_over_circle, opts.gain_tolerance
        ),
    )


def _program_of(recording, program):
    prog = program or recording.program
    if prog is None:
        raise AnalysisError("the recording has no test program: give one (--program)")
    if recording.n_samples < 10 or recording.duration_s < prog.period_s:
        raise AnalysisError(
            f"the recording lasts {recording.duration_s:.1f} s, shorter than one circle "
            f"({prog.period_s:.2f} s): no motion to analyse"
        )
    return prog


def _direction(mean, i, n_cycles, outliers):
    fit = mean.fit
    return DirectionResult(
        theta_x_rad=float(fit.theta_x[i]),
        theta_y_rad=float(fit.theta_y[i]),
        squareness_rad=float(mean.squareness_rad[i]),
        amp_x_m_s2=float(mean.amp_x_m_s2[i]),
        amp_y_m_s2=float(mean.amp_y_m_s2[i]),
        cycles=int(n_cycles),
        outlier_fraction=outliers[i],
    )


def _cycle_temperatures(recording, t_s, t_ccw_s, t_cw_s, period_s):
    """Mean sensor temperature over each CCW and CW cycle; NaN without a channel. [degC]"""
    t_mid = np.concatenate([t_ccw_s, t_cw_s])
    if recording.temperature_c is None:
        means = np.full(t_mid.shape, np.nan)
    else:
        lo = np.searchsorted(t_s, t_mid - 0.5 * period_s)
        hi = np.searchsorted(t_s, t_mid + 0.5 * period_s)
        csum = np.concatenate([[0.0], np.cumsum(recording.temperature_c)])
        means = (csum[hi] - csum[lo]) / np.maximum(hi - lo, 1)
    return means[: len(t_ccw_s)], means[len(t_ccw_s) :]


def _per_cycle(cycles, recording, t_s, period_s):
    temperature_ccw, temperature_cw = _cycle_temperatures(
        recording, t_s, cycles.t_ccw_s, cycles.t_cw_s, period_s
    )
    return {
        "pair": cycles.pair,
        "squareness_rad": cycles.squareness_rad,
        "squareness_ccw_rad": cycles.squareness_ccw_rad,
        "squareness_cw_rad": cycles.squareness_cw_rad,
        "servo_mismatch_rad": cycles.servo_mismatch_rad,
        "eps_c_rad": cycles.eps_c_rad,
        "t_ccw_s": cycles.t_ccw_s,
        "t_cw_s": cycles.t_cw_s,
        "temperature_ccw_c": temperature_ccw,
        "temperature_cw_c": temperature_cw,
    }


def _traces(phi_grid, mean):
    fit = mean.fit
    return {
        "phi_grid": phi_grid,
        "ccw_x": mean.mean_x[0],
        "ccw_y": mean.mean_y[0],
        "cw_x": mean.mean_x[1],
        "cw_y": mean.mean_y[1],
        "mean_x": mean.mean_x.mean(axis=0),
        "mean_y": mean.mean_y.mean(axis=0),
        "ccw_x_params": fit.x.params[0],
        "ccw_y_params": fit.y.params[0],
        "cw_x_params": fit.x.params[1],
        "cw_y_params": fit.y.params[1],
    }
