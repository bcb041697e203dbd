"""Choices of the analysis, with the paper's as defaults."""

from dataclasses import dataclass

from imu_square.pipeline.fit import robust_norm


@dataclass(frozen=True)
class AnalysisOptions:
    """Choices of the analysis; the defaults are the paper's.

    Attributes
    ----------
    cutoff_hz : float
        Low-pass cutoff of the designed Butterworth filter. [Hz]
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
        Bootstrap resamples over cycles (0 to skip).
    seed : int
        Seed of the bootstrap.
    min_cycles : int
        Least usable cycles per direction.
    """

    cutoff_hz: float = 4.0
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

    def robust_norm(self):
        """The robust norm these options name (a ``statsmodels`` norm)."""
        return robust_norm(self.norm, self.tuning)

    def irls(self):
        """Keyword options of :func:`imu_square.pipeline.fit.fit_irls`."""
        return {
            "maxiter": self.maxiter,
            "tol": self.tol,
            "conv": self.conv,
            "freeze_scale_after": self.freeze_scale_after,
        }
