"""The machine's baseline and tonight's change against it.

The **baseline** is the machine's own ``theta_y - theta_x`` when the monitor
was set up: the mean of at least :data:`MIN_RUNS` valid runs. It is not a
reference method (ballbar, laser): those can *anchor* it
(:mod:`imu_square.monitor.baseline_setup`).

The change of a night against it (``docs/model.md``, "The measurand")::

    Delta = (S - B) / cos(2 eps_c,B)

where ``S`` is the night's ``theta_y - theta_x`` (corrected for the sensor's
thermal drift when the monitor has learnt it, :mod:`.drift`), ``B`` the
baseline's mean and ``eps_c,B`` its sensor rotation. With the sensor left in
place its own non-orthogonality cancels in ``S - B`` and the division makes
``Delta`` the machine's change. Its standard uncertainty combines the night's
and the baseline's, ``u = sqrt(u_S^2 + u_B^2) / |cos 2 eps_c,B|``, with
Welch-Satterthwaite degrees of freedom.

The baseline's uncertainty is ``u_B^2 = max(s^2, mean(u_k^2)) / n``: the
larger of the runs' observed scatter ``s`` and their stated uncertainties, so
that three runs that happen to agree closely do not make it overconfident.

A sensor remount shows as a jump of ``eps_c``: beyond :data:`REMOUNT_SIGMAS`
times the night-to-night scatter of the baseline runs' ``eps_c``, and at least
:data:`REMOUNT_FLOOR_RAD` (:func:`remount_tolerance`), the sensor's own
non-orthogonality may have changed too, so the change is no longer the
machine's: the baseline is stale. The scatter, not each run's stated ``u`` of
``eps_c``, sets the tolerance: that ``u`` holds the anchors' timing, which
is common to the nights and cancels in a comparison (it is 300 times the
night-to-night scatter at 0.9 m/s², and would hide a 0.4° remount).
"""

import math
from dataclasses import dataclass

import numpy as np

from imu_square.errors import ImuSquareError

MIN_RUNS = 3
# eps_c of a night beyond this many times the baseline runs' scatter: remounted ...
REMOUNT_SIGMAS = 8.0
# ... and by at least this much, however steady the baseline's runs were. [rad]
REMOUNT_FLOOR_RAD = math.radians(0.02)


class BaselineError(ImuSquareError):
    """A baseline cannot be set from the runs given."""


@dataclass(frozen=True)
class RunValue:
    """What the baseline and the change need from one analysed run.

    Attributes
    ----------
    squareness_rad, u_squareness_rad : float
        ``theta_y - theta_x`` and its standard uncertainty. [rad]
    dof : int
        Degrees of freedom of ``u_squareness_rad``.
    eps_c_rad, u_eps_c_rad : float
        Sensor rotation and its standard uncertainty. [rad]
    recorded_at : str
        When the run was recorded (ISO 8601, UTC).
    """

    squareness_rad: float
    u_squareness_rad: float
    dof: int
    eps_c_rad: float
    u_eps_c_rad: float
    recorded_at: str


@dataclass(frozen=True)
class Baseline:
    """A machine's baseline.

    Attributes
    ----------
    squareness_rad : float
        Mean ``theta_y - theta_x`` of its runs. [rad]
    sd_rad : float
        Sample standard deviation of its runs. [rad]
    u_squareness_rad : float
        Standard uncertainty of the mean (module docstring). [rad]
    dof : int
        Degrees of freedom of ``u_squareness_rad``.
    eps_c_rad, u_eps_c_rad : float
        Mean sensor rotation and its standard uncertainty. [rad]
    n_runs : int
        Runs it was set from.
    first_recorded_at, last_recorded_at : str
        Dates of its first and last run (ISO 8601, UTC).
    """

    squareness_rad: float
    sd_rad: float
    u_squareness_rad: float
    dof: int
    eps_c_rad: float
    u_eps_c_rad: float
    n_runs: int
    first_recorded_at: str
    last_recorded_at: str

    @property
    def cos_2eps_c(self):
        """``cos(2 eps_c)`` of the baseline's sensor mounting."""
        return math.cos(2 * self.eps_c_rad)


@dataclass(frozen=True)
class Change:
    """A night's change of the machine's squareness against the baseline.

    Attributes
    ----------
    change_rad, u_change_rad : float
        ``Delta`` and its standard uncertainty (module docstring). [rad]
    dof : float
        Welch-Satterthwaite degrees of freedom of ``u_change_rad``.
    remounted : bool
        Whether ``eps_c`` moved beyond what a remount-free night allows.
    eps_c_shift_rad : float
        The night's ``eps_c`` minus the baseline's. [rad]
    """

    change_rad: float
    u_change_rad: float
    dof: float
    remounted: bool
    eps_c_shift_rad: float

    @property
    def z(self):
        """The standardised change ``Delta / u``."""
        return self.change_rad / self.u_change_rad


def compute_baseline(runs):
    """The baseline of valid runs.

    Parameters
    ----------
    runs : sequence of RunValue
        The runs, at least :data:`MIN_RUNS`, all valid.

    Returns
    -------
    Baseline

    Raises
    ------
    BaselineError
        Fewer than :data:`MIN_RUNS` runs, or runs whose ``eps_c`` disagree (the
        sensor was moved among them).
    """
    if len(runs) < MIN_RUNS:
        raise BaselineError(f"a baseline needs at least {MIN_RUNS} valid runs, got {len(runs)}")
    s = np.array([r.squareness_rad for r in runs])
    u = np.array([r.u_squareness_rad for r in runs])
    eps = np.array([r.eps_c_rad for r in runs])
    u_eps = np.array([r.u_eps_c_rad for r in runs])
    n = s.size
    sd = float(np.std(s, ddof=1))
    stated = float(np.mean(u**2))
    if sd**2 >= stated:
        u_mean, dof = sd / math.sqrt(n), n - 1
    else:  # the stated uncertainties dominate: their own degrees of freedom
        u_mean, dof = math.sqrt(stated / n), int(sum(r.dof for r in runs))
    eps_mean = float(np.mean(eps))
    # a remount among them would inflate their own scatter: each against the median
    spread = np.abs(eps - np.median(eps))
    if np.any(spread > REMOUNT_FLOOR_RAD):
        k = int(np.argmax(spread))
        raise BaselineError(
            f"the sensor moved among the baseline's runs: eps_c of the run of "
            f"{runs[k].recorded_at} is {math.degrees(eps[k]):.3f} deg against a mean of "
            f"{math.degrees(eps_mean):.3f} deg; set the baseline from runs of one mounting"
        )
    u_eps_mean = math.sqrt(max(float(np.var(eps, ddof=1)), float(np.mean(u_eps**2))) / n)
    dates = sorted(r.recorded_at for r in runs)
    return Baseline(
        squareness_rad=float(np.mean(s)),
        sd_rad=sd,
        u_squareness_rad=u_mean,
        dof=int(dof),
        eps_c_rad=eps_mean,
        u_eps_c_rad=u_eps_mean,
        n_runs=n,
        first_recorded_at=dates[0],
        last_recorded_at=dates[-1],
    )


def remount_tolerance(baseline_eps_rad):
    """The largest ``eps_c`` shift from the baseline's that is not a remount.

    Parameters
    ----------
    baseline_eps_rad : sequence of float
        ``eps_c`` of the baseline's runs. [rad]

    Returns
    -------
    float
        ``max(REMOUNT_SIGMAS sd sqrt(1 + 1/n), REMOUNT_FLOOR_RAD)``. [rad]
    """
    eps = np.asarray(baseline_eps_rad, dtype=np.float64)
    sd = float(np.std(eps, ddof=1)) if eps.size > 1 else 0.0
    return max(REMOUNT_SIGMAS * sd * math.sqrt(1.0 + 1.0 / eps.size), REMOUNT_FLOOR_RAD)


def change_since(baseline, run, eps_tolerance_rad=REMOUNT_FLOOR_RAD):
    """A night's change against the baseline.

    Parameters
    ----------
    baseline : Baseline
        The machine's baseline.
    run : RunValue
        The night (its ``squareness_rad`` already corrected for drift, if the
        monitor corrects it).
    eps_tolerance_rad : float
        The largest ``eps_c`` shift that is not a remount (:func:`remount_tolerance`). [rad]

    Returns
    -------
    Change
    """
    c = baseline.cos_2eps_c
    var_s, var_b = run.u_squareness_rad**2, baseline.u_squareness_rad**2
    u = math.sqrt(var_s + var_b) / abs(c)
    dof = (var_s + var_b) ** 2 / (var_s**2 / max(run.dof, 1) + var_b**2 / max(baseline.dof, 1))
    shift = run.eps_c_rad - baseline.eps_c_rad
    allowed = max(eps_tolerance_rad, REMOUNT_FLOOR_RAD)
    return Change(
        change_rad=(run.squareness_rad - baseline.squareness_rad) / c,
        u_change_rad=u,
        dof=float(dof),
        remounted=abs(shift) > allowed,
        eps_c_shift_rad=shift,
    )
