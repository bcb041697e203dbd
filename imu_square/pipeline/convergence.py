"""Convergence of the mean squareness over repeated runs (paper, Fig. 6 [1]_).

References
----------
.. [1] K. Szipka, A. Archenti, G. W. Vogl, M. A. Donmez, CIRP Annals 68 (2019).
"""

from dataclasses import dataclass

import numpy as np

from imu_square.units import URAD


@dataclass(frozen=True)
class Convergence:
    """Running mean and type A uncertainty after 1, 2, ... runs.

    Attributes
    ----------
    n_runs : ndarray of int, shape (n,)
        Number of runs included.
    mean_rad : ndarray, shape (n,)
        Mean squareness of the first ``n_runs`` runs. [rad]
    u_mean_rad : ndarray, shape (n,)
        Type A standard uncertainty of that mean, ``s / sqrt(n)`` (NaN for one run). [rad]
    """

    n_runs: np.ndarray
    mean_rad: np.ndarray
    u_mean_rad: np.ndarray

    def to_json_dict(self):
        """Lists in µrad, NaN as None."""
        return {
            "n_runs": self.n_runs.tolist(),
            "mean_urad": (self.mean_rad / URAD).tolist(),
            "u_mean_urad": [None if np.isnan(u) else u / URAD for u in self.u_mean_rad],
        }


def convergence(values_rad):
    """Running mean and its type A uncertainty over runs, in order.

    Parameters
    ----------
    values_rad : sequence of float
        Squareness of each run, in the order they were measured. [rad]

    Returns
    -------
    Convergence
    """
    v = np.asarray(values_rad, dtype=np.float64)
    n = np.arange(1, v.size + 1)
    mean = np.cumsum(v) / n
    sq = np.cumsum(v**2)
    with np.errstate(invalid="ignore", divide="ignore"):
        var = np.where(n > 1, (sq - n * mean**2) / (n - 1), np.nan)
        u = np.sqrt(np.maximum(var, 0.0)) / np.sqrt(n)
    u[0] = np.nan
    return Convergence(n_runs=n, mean_rad=mean, u_mean_rad=u)
