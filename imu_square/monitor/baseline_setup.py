"""Setting a machine's baseline and anchoring it by a reference method.

``imu-square baseline set`` takes at least :data:`~.baseline.MIN_RUNS` valid
runs (recordings, analysed and stored if new, or run ids of the history) and
stores their mean, spread and uncertainty with the alarm design made for it.
``imu-square baseline anchor`` ties the baseline to an absolute machine
squareness measured by a reference method while the baseline was taken: a
ballbar's value, or the two face-diagonal lengths of an ISO 230-6 laser test.
"""

import math

from imu_square.errors import ImuSquareError, MonitorError, step
from imu_square.monitor.history.rows import AnchorRow, BaselineRow
from imu_square.monitor.night import recording_row, store_run
from imu_square.monitor.stats.baseline import BaselineError, compute_baseline
from imu_square.monitor.verdict import design_for, run_value
from imu_square.units import MM, URAD

# A machine tool squareness beyond 1 mm/m is a unit mistake, not a machine. [µm/m]
MAX_ANCHOR_UM_PER_M = 1000.0


def runs_for_baseline(config, history, items, program=None):
    """The runs named by recording paths or run ids; new recordings analysed, not yet stored.

    Parameters
    ----------
    config : MonitorConfig
        The monitor file.
    history : History
        The open history.
    items : sequence of str
        Recording paths, or run ids as whole numbers.
    program : TestProgram, optional
        The program the monitor expects.

    Returns
    -------
    runs : list of RunRow
        Stored runs, and new ones (``id`` None) that :func:`set_baseline`
        stores with the baseline, in one transaction: a refused baseline
        stores nothing.
    diagnostics : dict of str to DiagnosticFitRow
        The diagnostic fits of the recordings given, by SHA-256, for
        :func:`set_baseline` to store with their runs.

    Raises
    ------
    BaselineError
        A run that is invalid, unknown, or of another machine.
    """
    from pathlib import Path

    from imu_square.errors import HistoryError

    rows, diagnostics = [], {}
    for item in items:
        if item.isdigit():
            try:
                row = history.run(int(item))
            except HistoryError:
                raise BaselineError(f"run {item} is not in the history") from None
        else:
            path = Path(item).absolute()
            row, _, fit = recording_row(config, path, program)
            if fit is not None:
                diagnostics[row.recording_sha256] = fit
            stored = history.run_by_hash(config.machine_id, row.recording_sha256, row.settings_hash)
            row = stored or row
        where = row.recording_path if row.id is None else f"run {row.id} ({row.recording_path})"
        if row.machine_id != config.machine_id:
            raise BaselineError(
                f"{where} is of machine {row.machine_id!r}, not {config.machine_id!r}"
            )
        if not row.valid:
            raise BaselineError(
                f"{where} is invalid ({row.invalid_reason}): an invalid run never enters a baseline"
            )
        rows.append(row)
    return rows, diagnostics


def set_baseline(config, history, runs, note="", diagnostics=None):
    """Compute, store and design the baseline of valid runs.

    Parameters
    ----------
    config : MonitorConfig
        The monitor file.
    history : History
        The open history.
    runs : sequence of RunRow
        Valid runs of the machine; those not yet stored (``id`` None) are
        stored with the baseline, in one transaction.
    note : str
        Free text kept with it.
    diagnostics : dict of str to DiagnosticFitRow, optional
        Diagnostic fits to store with the runs, by their recordings' SHA-256.

    Returns
    -------
    BaselineRow
        As stored, with its alarm design.
    """
    diagnostics = diagnostics or {}
    keys = [r.recording_sha256 for r in runs]
    if len(set(keys)) != len(keys):
        raise BaselineError("the same recording is given twice: a baseline needs distinct runs")
    stats = compute_baseline([run_value(r) for r in runs])  # refuses before storing anything
    # designed before anything is stored: a design that fails leaves the history as it was
    with step("designing the alarm charts", MonitorError):
        design = design_for(stats.eps_c_rad, stats.u_squareness_rad, runs, config.alarms)
    with history.transaction():
        ids = tuple(
            store_run(history, r, diagnostics.get(r.recording_sha256))[0]
            if r.id is None or r.recording_sha256 in diagnostics
            else r.id
            for r in runs
        )
        baseline_id = history.add_baseline(
            BaselineRow(
                machine_id=config.machine_id,
                run_ids=ids,
                squareness_mean_rad=stats.squareness_rad,
                squareness_sd_rad=stats.sd_rad,
                u_squareness_mean_rad=stats.u_squareness_rad,
                eps_c_rad=stats.eps_c_rad,
                u_eps_c_rad=stats.u_eps_c_rad,
                dof=float(stats.dof),
                note=note,
                alarm_design=design.to_json_dict(),
            )
        )
    return history.baseline(baseline_id)


def anchor_by_ballbar(history, baseline_row, value_um_per_m, u_um_per_m=None, note=""):
    """Anchor the baseline with a ballbar's squareness.

    Parameters
    ----------
    history : History
        The open history.
    baseline_row : BaselineRow
        The baseline anchored.
    value_um_per_m : float
        The ballbar's squareness of the machine (Renishaw sign). [µm/m]
    u_um_per_m : float, optional
        Its standard uncertainty. [µm/m]
    note : str
        Free text.

    Returns
    -------
    AnchorRow
    """
    if not (math.isfinite(value_um_per_m) and abs(value_um_per_m) <= MAX_ANCHOR_UM_PER_M):
        raise ImuSquareError(
            f"--ballbar must be a machine squareness in µm/m within ±{MAX_ANCHOR_UM_PER_M:g}, "
            f"got {value_um_per_m!r}"
        )
    if u_um_per_m is not None and not (math.isfinite(u_um_per_m) and u_um_per_m > 0):
        raise ImuSquareError(f"--u must be a standard uncertainty > 0 in µm/m, got {u_um_per_m!r}")
    row = AnchorRow(
        baseline_id=baseline_row.id,
        method="ballbar",
        value_rad=value_um_per_m * URAD,
        u_value_rad=None if u_um_per_m is None else u_um_per_m * URAD,
        input={"ballbar_um_per_m": value_um_per_m, "u_um_per_m": u_um_per_m},
        note=note,
    )
    anchor_id = history.add_anchor(row)
    return next(a for a in history.anchors(baseline_row.id) if a.id == anchor_id)


def anchor_by_diagonals(history, baseline_row, lengths_mm, travels_mm, note=""):
    """Anchor the baseline with ISO 230-6 face-diagonal lengths (laser).

    ``S = D0 (D1 - D2) / (2 X Y)``
    (:func:`~imu_square.reference.diagonal.squareness_from_diagonals`), with D1
    the diagonal from (x_max, y_min) to (x_min, y_max), stretched by a positive
    squareness.

    Parameters
    ----------
    history : History
        The open history.
    baseline_row : BaselineRow
        The baseline anchored.
    lengths_mm : sequence of 2 float
        Measured lengths of D1 and D2. [mm]
    travels_mm : sequence of 2 float
        Programmed X and Y travels of the diagonals' rectangle. [mm]
    note : str
        Free text.

    Returns
    -------
    AnchorRow
    """
    from imu_square.reference.diagonal import squareness_from_diagonals

    if len(lengths_mm) != 2 or len(travels_mm) != 2:
        raise ImuSquareError(
            f"--diagonals takes the two face-diagonal lengths D1 D2 and --travel-mm the X and Y "
            f"travels, got {len(lengths_mm)} and {len(travels_mm)} numbers"
        )
    x, y = travels_mm
    if not (math.isfinite(x) and math.isfinite(y) and x > 0 and y > 0):
        raise ImuSquareError(f"--travel-mm must be two numbers > 0, got {list(travels_mm)!r}")
    nominal = math.hypot(x, y)
    for d in lengths_mm:
        if not (math.isfinite(d) and abs(d / nominal - 1) < 1e-3):
            raise ImuSquareError(
                f"--diagonals: a face diagonal of {x:g} x {y:g} mm is {nominal:.4f} mm long; "
                f"got {d!r} mm, more than 0.1 % off (check the units: mm)"
            )
    value = squareness_from_diagonals(lengths_mm[0] * MM, lengths_mm[1] * MM, (x * MM, y * MM))
    row = AnchorRow(
        baseline_id=baseline_row.id,
        method="diagonals",
        value_rad=float(value),
        input={"lengths_mm": list(lengths_mm), "travels_mm": list(travels_mm)},
        note=note,
    )
    anchor_id = history.add_anchor(row)
    return next(a for a in history.anchors(baseline_row.id) if a.id == anchor_id)
