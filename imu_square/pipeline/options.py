"""Choices of the analysis, with the paper's as defaults."""

from dataclasses import dataclass

from imu_square.errors import AnalysisError
from imu_square.pipeline.sine_fit import robust_norm


@dataclass(frozen=True)
class AnalysisOptions:
    """Choices of the analysis; the defaults are the paper's.

    Attributes
    ----------
    cutoff_hz : float or None
        Low-pass cutoff of the designed Butterworth filter; None ties it to the
        circle: 8 pi times the circle frequency, the paper's 4 Hz at its
        0.159 Hz circle (:func:`imu_square.pipeline.filter.circle_cutoff_hz`). [Hz]
    order : int
        Order of the designed filter (applied forward and backward).
    norm : {"tukey", "huber", "ols"}
        Robust norm of the sine fits; the paper's bisquare is ``"tukey"``.
    tuning : float or None
        Tuning constant of the norm, in robust-scale units; norm default if None.
    maxiter : int
        IRLS iteration limit.
    freeze_scale_after : int
        Iterations after which a fit that has not converged keeps its scale
        fixed: statsmodels' algorithm until then, and a guaranteed descent after
        (the median-based scale can otherwise make single noisy cycles cycle).
    conv : {"coefs", "dev"}
        IRLS convergence criterion. ``statsmodels``' default "dev" compares
        ``rho(resid / s2)`` with ``s2`` the residual *variance*, which for
        residuals of 1e-5 m/s^2 saturates ``rho`` and may never settle; the
        pipeline stops on the change of every coefficient instead.
    tol : float
        IRLS convergence tolerance; for "coefs" in m/s^2 (1e-10 m/s^2 on an
        amplitude of 0.1 m/s^2 is 1e-9 rad of phase).
    grid_points : int
        Points of the common phi grid per cycle.
    bootstrap_n : int
        Bootstrap resamples over cycles (0 to skip, else at least 2).
    seed : int
        Seed of the bootstrap.
    min_cycles : int
        Least usable cycles per direction.
    gain_tolerance : float
        Largest relative error of the sensor's mean x/y gain, which bounds the
        servos' amplitude share of the result (:mod:`imu_square.pipeline.servo`).
    coverage_probability : float
        Probability of the expanded uncertainty (Student's t on the cycle pairs).
    """

    cutoff_hz: float | None = None
    order: int = 1
    norm: str = "tukey"
    tuning: float | None = None
    maxiter: int = 200
    freeze_scale_after: int = 50
    conv: str = "coefs"
    tol: float = 1e-10
    grid_points: int = 512
    bootstrap_n: int = 200
    seed: int = 0
    min_cycles: int = 3
    gain_tolerance: float = 0.01
    coverage_probability: float = 0.95

    def __post_init__(self):
        if not 0.0 <= self.gain_tolerance < 0.5:
            raise AnalysisError(f"gain_tolerance must be in [0, 0.5), got {self.gain_tolerance!r}")
        if self.bootstrap_n == 1 or self.bootstrap_n < 0:  # one resample has no spread
            raise AnalysisError(
                f"bootstrap_n must be 0 (no bootstrap) or at least 2, got {self.bootstrap_n!r}"
            )
        if not 0.0 < self.coverage_probability < 1.0:
            raise AnalysisError(
                f"coverage_probability must be in (0, 1), got {self.coverage_probability!r}"
            )

    def robust_norm(self):
        """The robust norm these options name.

        Returns
        -------
        statsmodels.robust.norms.RobustNorm
        """
        return robust_norm(self.norm, self.tuning)

    def irls(self):
        """Keyword options of :func:`imu_square.pipeline.sine_fit.fit_irls`.

        Returns
        -------
        dict of str to object
            ``maxiter``, ``tol``, ``conv`` and ``freeze_scale_after``.
        """
        return {
            "maxiter": self.maxiter,
            "tol": self.tol,
            "conv": self.conv,
            "freeze_scale_after": self.freeze_scale_after,
        }
