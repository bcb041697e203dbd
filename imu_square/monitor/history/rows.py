"""What one row of the monitor's history holds: a run, a baseline, an anchor, a verdict, an
alert, a night's diagnostics.

The rows are frozen dataclasses, checked and normalised when they are built,
so that a row reads back from either backend exactly as it was stored:

- times are integer nanoseconds since the Unix epoch, UTC (fields ``*_ns``),
  like the times in MCAP (:mod:`imu_square.monitor.history.encoding` converts);
- a float field holds a Python float or None (NULL); NaN becomes None, since
  SQLite stores NaN as NULL anyway, and -0.0 becomes 0.0;
- text fields are UTF-8 without NUL (PostgreSQL's text refuses NUL);
- the JSON fields (``settings``, ``quality``, ``warnings``, ``per_cycle``,
  ``result``, ``input``, ``statistics``) hold JSON values only, by
  :func:`~imu_square.json_values.json_safe`'s rules. They are stored as canonical JSON text
  (:func:`~imu_square.monitor.history.encoding.canonical_json`), byte-identical
  whichever backend or process wrote them. Treat them as read-only.

A field ``id`` or ``created_at_ns`` left None is filled in by the store.
"""

import math
import os
import re
from dataclasses import MISSING, dataclass, field, fields
from functools import partial

from imu_square import __version__
from imu_square.errors import HistoryError
from imu_square.json_values import JsonValueError, json_safe
from imu_square.monitor.history.encoding import datetime_from_ns, settings_hash
from imu_square.validation import (
    check_bool,
    check_int,
    check_number,
    check_option,
    check_text,
    fail,
    is_number,
)

#: The monitor's verdicts on a run (issue 11, section 5).
EVALUATION_STATES = ("ok", "warning", "alarm", "invalid", "stale_baseline", "no_baseline")
#: The reference methods an anchor can come from.
ANCHOR_METHODS = ("ballbar", "diagonals")
#: What became of an alert at a sink: waiting, delivered, refused as a configuration error.
OUTBOX_STATES = ("pending", "delivered", "rejected")

_SHA256 = re.compile(r"[0-9a-f]{64}")


# --- field checks: each takes "Row.field" and the value, and returns it normalised or raises
# naming the row and field, what is allowed and what came ---


def _storable(where, value):
    """Text both backends store as it is: UTF-8 (no lone surrogates from undecodable
    file names) and no NUL, which PostgreSQL's text refuses."""
    if not isinstance(value, str):
        raise HistoryError(f"{where} must be text, got {value!r}")
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        raise HistoryError(f"{where} must be UTF-8 text, got {value!r}") from None
    if "\x00" in value:
        raise HistoryError(f"{where} must not hold a NUL character, got {value!r}")
    return value


def _text(where, value):
    if isinstance(value, os.PathLike):
        value = os.fspath(value)
    # a file name is stored as it was given: a tab is allowed, a line break is not
    check_text(where, value, controls=True, error=HistoryError)
    return _storable(where, value)


def _one_line(where, value):
    """Whitespace runs (newlines too) collapse to one space: a reason is one line."""
    if value is None:
        return None
    return " ".join(_storable(where, value).split()) or None


def _float(where, value, required=False):
    if value is None or (is_number(value) and math.isnan(value)):  # NaN is NULL
        if required:
            fail(where, "a number", value, error=HistoryError)
        return None
    # -0.0 is 0.0 (SQLite keeps an integral REAL as an integer)
    return check_number(where, value, -math.inf, math.inf, error=HistoryError) + 0.0


def _int(where, value, required=False, minimum=None):
    if value is None and not required:
        return None
    # BIGINT, and nanoseconds up to the year 2262
    bits = "a 64-bit integer"
    value = check_int(
        where, value, -(2**63), 2**63 - 1, kind="an integer", allowed=bits, error=HistoryError
    )
    if minimum is not None and value < minimum:
        fail(where, f"at least {minimum}", value, error=HistoryError)
    return value


def _json(where, value, kind=dict):
    try:
        value = json_safe(value, where)
    except JsonValueError as exc:
        raise HistoryError(
            f"{where} must hold JSON values (dicts, lists, text, numbers), "
            f"got a {type(exc.value).__name__}: {exc.value!r}"
        ) from None
    if not isinstance(value, kind):
        raise HistoryError(f"{where} must be a JSON {kind.__name__}, got {type(value).__name__}")
    return value


def _texts(where, value):
    value = _json(where, value, list)
    if not all(isinstance(w, str) for w in value):
        raise HistoryError(f"{where} must be text, got {value!r}")
    return tuple(value)


def _sha256(where, value, required=True):
    if value is None and not required:
        return None
    text = value.lower() if isinstance(value, str) else value
    if not isinstance(text, str) or not _SHA256.fullmatch(text):
        raise HistoryError(f"{where} must be 64 hexadecimal digits, got {value!r}")
    return text


def _run_ids(where, ids):
    if isinstance(ids, str | bytes) or not hasattr(ids, "__iter__"):
        raise HistoryError(f"{where} must be run ids, got {ids!r}")
    what = "one or more run ids"
    ids = tuple(check_int(where, i, kind=what, error=HistoryError) for i in ids)
    if not ids:
        fail(where, what, ids, error=HistoryError)
    if len(set(ids)) != len(ids):
        raise HistoryError(f"{where} must not repeat a run, got {ids!r}")
    return tuple(sorted(ids))


def _option(*allowed):
    return lambda where, value: check_option(where, value, allowed, error=HistoryError)


# The check of a field by its annotation, unless the field names its own (_checked).
_BY_TYPE = {
    int | None: _int,
    int: partial(_int, required=True),
    float | None: _float,
    float: partial(_float, required=True),
    str: _text,
    str | None: _one_line,
    bool: lambda where, value: check_bool(where, value, error=HistoryError),
    dict: _json,
    tuple: _texts,
}


def _checked(check=None, default=MISSING, **kw):
    """A field checked by ``check`` (default: by its annotation) with the options ``kw``.

    ``required_if="valid"`` makes the field required when the row's ``valid`` is true.
    """
    return field(default=default, metadata={"check": check, **kw})


def _check_fields(row):
    """Check and normalise every field of ``row`` in field order (see :data:`_BY_TYPE`)."""
    for f in fields(row):
        kw = dict(f.metadata)
        check = kw.pop("check", None) or _BY_TYPE[f.type]
        if "required_if" in kw:
            kw["required"] = bool(getattr(row, kw.pop("required_if")))
        value = check(f"{type(row).__name__}.{f.name}", getattr(row, f.name), **kw)
        object.__setattr__(row, f.name, value)


@dataclass(frozen=True, kw_only=True)
class RunRow:
    """One analysed run of one machine.

    Attributes
    ----------
    id : int or None
        Row id; None until stored.
    machine_id : str
        The machine the run was recorded on.
    recording_path : str
        The recording as the caller named it (stored as given).
    recording_sha256 : str
        SHA-256 of the recording's bytes (:func:`file_sha256`).
    settings : dict
        The analysis settings the run was analysed with (JSON values).
    settings_hash : str or None
        :func:`settings_hash` of ``settings``; computed when None.
    software_version : str
        imu-square's version that analysed the run.
    recorded_at_ns : int or None
        When the recording started, UTC; None only for a file too broken to
        tell (such a run sorts last). [ns]
    analysed_at_ns : int or None
        When the analysis ran, UTC; stamped by the store when None. [ns]
    valid : bool
        False for a run that failed quality: it never enters a baseline or an
        alarm statistic.
    invalid_reason : str or None
        Why the run is invalid, one line; None for a valid run.
    squareness_rad, u_squareness_rad : float or None
        ``theta_y - theta_x`` (paper, Eq. 4) and its type A standard
        uncertainty; required for a valid run. [rad]
    u_squareness_bootstrap_rad : float or None
        Bootstrap standard deviation over cycles. [rad]
    dof : float or None
        Degrees of freedom of ``u_squareness_rad``.
    crb_rad : float or None
        Cramér-Rao bound of ``squareness_rad``. [rad]
    theta_x_rad, theta_y_rad : float or None
        Fitted phases. [rad]
    eps_c_rad, u_eps_c_rad : float or None
        Sensor rotation about Z and its uncertainty. [rad]
    servo_mismatch_rad, u_servo_mismatch_rad : float or None
        Servo mismatch and its uncertainty. [rad]
    noise_density_m_s2_rthz : float or None
        Noise density behind ``crb_rad``. [m/s^2/sqrt(Hz)]
    amp_x_m_s2, amp_y_m_s2 : float or None
        Fitted amplitudes. [m/s^2]
    temperature_start_c, temperature_end_c, temperature_mean_c : float or None
        Sensor temperature at the start, at the end and on average. [degC]
    time_since_power_on_s : float or None
        Time from the sensor's power-on to the recording's start. [s]
    cycles_ccw, cycles_cw : int or None
        Cycles used per direction.
    quality : dict
        Quality flags.
    warnings : tuple of str
        Human-readable warnings.
    per_cycle : dict
        Per cycle-pair values and times, for the drift regression.
    result : dict
        The whole ``RunResult.to_json_dict()``.
    """

    id: int | None = _checked(default=None, minimum=1)
    machine_id: str
    recording_path: str
    recording_sha256: str = _checked(_sha256)
    settings: dict
    settings_hash: str | None = _checked(_sha256, default=None, required=False)
    software_version: str = __version__
    recorded_at_ns: int | None
    analysed_at_ns: int | None = None
    valid: bool
    invalid_reason: str | None = None
    # a valid run has a squareness and its uncertainty
    squareness_rad: float | None = _checked(default=None, required_if="valid")
    u_squareness_rad: float | None = _checked(default=None, required_if="valid")
    u_squareness_bootstrap_rad: float | None = None
    dof: float | None = None
    crb_rad: float | None = None
    theta_x_rad: float | None = None
    theta_y_rad: float | None = None
    eps_c_rad: float | None = None
    u_eps_c_rad: float | None = None
    servo_mismatch_rad: float | None = None
    u_servo_mismatch_rad: float | None = None
    noise_density_m_s2_rthz: float | None = None
    amp_x_m_s2: float | None = None
    amp_y_m_s2: float | None = None
    temperature_start_c: float | None = None
    temperature_end_c: float | None = None
    temperature_mean_c: float | None = None
    time_since_power_on_s: float | None = None
    cycles_ccw: int | None = _checked(default=None, minimum=0)
    cycles_cw: int | None = _checked(default=None, minimum=0)
    quality: dict = field(default_factory=dict)
    warnings: tuple = ()
    per_cycle: dict = field(default_factory=dict)
    result: dict = field(default_factory=dict, repr=False)

    def __post_init__(self):
        _check_fields(self)
        if self.settings_hash is None:
            object.__setattr__(self, "settings_hash", settings_hash(self.settings))
        if self.valid:
            if self.invalid_reason is not None:
                raise HistoryError(
                    f"RunRow.invalid_reason must be None for a valid run, got "
                    f"{self.invalid_reason!r}"
                )
        elif self.invalid_reason is None:
            raise HistoryError("RunRow.invalid_reason must say why an invalid run is invalid")

    @property
    def recorded_at(self):
        """When the recording started (aware UTC datetime, or None)."""
        return datetime_from_ns(self.recorded_at_ns)


#: RunRow's float fields, in the order of the table's columns.
RUN_FLOAT_FIELDS = tuple(f.name for f in fields(RunRow) if f.type == float | None)


@dataclass(frozen=True, kw_only=True)
class BaselineRow:
    """A machine's baseline: its own squareness when the monitor was set up.

    The machine's current baseline is its latest; a stale one stays current
    (the monitor then says ``stale_baseline``) until a new one is set.

    Attributes
    ----------
    id : int or None
        Row id; None until stored.
    machine_id : str
        The machine.
    run_ids : tuple of int
        The valid runs it was set from, all analysed with the same settings.
    squareness_mean_rad : float
        Mean of the runs' ``squareness_rad``. [rad]
    squareness_sd_rad : float or None
        Standard deviation of the runs' ``squareness_rad`` (their spread). [rad]
    u_squareness_mean_rad : float
        Standard uncertainty of the mean. [rad]
    eps_c_rad, u_eps_c_rad : float or None
        Sensor rotation about Z and its uncertainty, to tell a remount. [rad]
    dof : float or None
        Degrees of freedom of ``u_squareness_mean_rad``.
    settings_hash : str or None
        The runs' settings hash; the store fills it in from the runs.
    first_run_at_ns, last_run_at_ns : int or None
        Recording times of the first and the last run; the store fills them
        in from the runs. [ns]
    stale : bool
        True once the sensor was found remounted (see ``stale_reason``).
    stale_reason : str or None
        Why the baseline went stale, one line.
    stale_at_ns : int or None
        When it was marked stale. [ns]
    note : str
        Free text from the user.
    created_at_ns : int or None
        When it was set; stamped by the store when None. [ns]
    alarm_design : dict
        The alarm charts designed for this baseline
        (:meth:`~imu_square.monitor.stats.alarms.AlarmDesign.to_json_dict`); empty until
        designed.
    diagnostic_designs : dict
        The alarm charts designed for the diagnostics with an alarm, by name
        (:mod:`imu_square.monitor.diagnostics.alarms`); each made once, when first needed.
    """

    id: int | None = _checked(default=None, minimum=1)
    machine_id: str
    run_ids: tuple = _checked(_run_ids)
    squareness_mean_rad: float
    squareness_sd_rad: float | None = None
    u_squareness_mean_rad: float
    eps_c_rad: float | None = None
    u_eps_c_rad: float | None = None
    dof: float | None = None
    settings_hash: str | None = _checked(_sha256, default=None, required=False)
    first_run_at_ns: int | None = None
    last_run_at_ns: int | None = None
    stale: bool = False
    stale_reason: str | None = None
    stale_at_ns: int | None = None
    note: str = _checked(_storable, default="")
    created_at_ns: int | None = None
    alarm_design: dict = field(default_factory=dict)
    diagnostic_designs: dict = field(default_factory=dict)

    def __post_init__(self):
        _check_fields(self)
        if self.stale and self.stale_reason is None:
            raise HistoryError("BaselineRow.stale_reason must say why a stale baseline is stale")

    @property
    def created_at(self):
        """When the baseline was set (aware UTC datetime, or None)."""
        return datetime_from_ns(self.created_at_ns)


@dataclass(frozen=True, kw_only=True)
class AnchorRow:
    """An absolute anchor of a baseline by a reference method.

    Attributes
    ----------
    id : int or None
        Row id; None until stored.
    baseline_id : int
        The baseline it anchors.
    method : {"ballbar", "diagonals"}
        The reference method.
    value_rad : float
        The machine's squareness the method gave (``machine_squareness_rad``). [rad]
    u_value_rad : float or None
        Its standard uncertainty. [rad]
    input : dict
        The raw numbers the user gave (JSON values).
    note : str
        Free text from the user.
    created_at_ns : int or None
        When it was stored; stamped by the store when None. [ns]
    """

    id: int | None = _checked(default=None, minimum=1)
    baseline_id: int = _checked(minimum=1)
    method: str = _checked(_option(*ANCHOR_METHODS))
    value_rad: float
    u_value_rad: float | None = None
    input: dict = field(default_factory=dict)
    note: str = _checked(_storable, default="")
    created_at_ns: int | None = None

    def __post_init__(self):
        _check_fields(self)


@dataclass(frozen=True, kw_only=True)
class EvaluationRow:
    """The monitor's verdict on one run against one baseline.

    Attributes
    ----------
    id : int or None
        Row id; None until stored.
    run_id : int
        The run judged.
    baseline_id : int or None
        The baseline it was judged against; None when there was none
        (``state`` is then ``no_baseline``, or ``invalid``).
    state : str
        One of :data:`EVALUATION_STATES`.
    change_rad, u_change_rad : float or None
        Change of ``squareness_rad`` since the baseline and its standard
        uncertainty. [rad]
    statistics : dict
        The alarm charts' statistics (Shewhart, EWMA, CUSUM, ...), JSON values.
    created_at_ns : int or None
        When the verdict was stored; stamped by the store when None. [ns]
    """

    id: int | None = _checked(default=None, minimum=1)
    run_id: int = _checked(minimum=1)
    baseline_id: int | None = _checked(default=None, minimum=1)
    state: str = _checked(_option(*EVALUATION_STATES))
    change_rad: float | None = None
    u_change_rad: float | None = None
    statistics: dict = field(default_factory=dict)
    created_at_ns: int | None = None

    def __post_init__(self):
        _check_fields(self)
        if self.baseline_id is None and self.state not in ("no_baseline", "invalid"):
            raise HistoryError(
                f"EvaluationRow.baseline_id must name the baseline of a {self.state!r} verdict"
            )
        if self.baseline_id is not None and self.state == "no_baseline":
            raise HistoryError(
                f"EvaluationRow.baseline_id must be None for 'no_baseline', got "
                f"{self.baseline_id!r}"
            )


@dataclass(frozen=True, kw_only=True)
class OutboxRow:
    """One alert for one sink, kept in the outbox until it is delivered.

    Attributes
    ----------
    id : int or None
        Row id; None until stored.
    machine_id : str
        The machine.
    alert_id : str
        The alert's id, the same in every sink and on every try (receivers dedupe on it).
    sink : str
        The sink's name in the monitor file.
    created_at_ns : int
        When the alert was made: pending alerts are delivered oldest first. [ns]
    alert : dict
        The alert as every sink sends it
        (:meth:`~imu_square.monitor.alerts.alert.Alert.as_dict`).
    state : str
        One of :data:`OUTBOX_STATES`: ``rejected`` is a configuration error,
        kept but not retried.
    attempts : int
        Tries so far, over every delivery round.
    last_error : str or None
        The last failure.
    claimed_by : str or None
        The delivery round that holds the alert now.
    claimed_until_ns : int or None
        When that claim runs out: then another round may take the alert
        (its process died mid-delivery). [ns]
    updated_at_ns : int or None
        When the row last changed; stamped by the store. [ns]
    """

    id: int | None = None
    machine_id: str
    alert_id: str
    sink: str
    created_at_ns: int
    alert: dict
    state: str = "pending"
    attempts: int = 0
    last_error: str | None = None
    claimed_by: str | None = None
    claimed_until_ns: int | None = None
    updated_at_ns: int | None = None

    def __post_init__(self):
        check_option("OutboxRow.state", self.state, OUTBOX_STATES)


@dataclass(frozen=True, kw_only=True)
class DiagnosticRow:
    """One diagnostic of one night's fit (:mod:`imu_square.monitor.diagnostics`).

    Attributes
    ----------
    id : int or None
        Row id; None until stored.
    fit_id : int or None
        The fit it belongs to; filled in by the store.
    name : str
        The diagnostic (:data:`~imu_square.monitor.diagnostics.catalog.CATALOG`).
    unit : str
        Its SI unit.
    value, u_value : float or None
        Its estimate and standard uncertainty; None when it is missing. [SI]
    missing_reason : str or None
        Why it is missing, one line; None when it has a value.
    """

    id: int | None = _checked(default=None, minimum=1)
    fit_id: int | None = _checked(default=None, minimum=1)
    name: str
    unit: str
    value: float | None = None
    u_value: float | None = None
    missing_reason: str | None = None

    def __post_init__(self):
        _check_fields(self)
        if (self.value is None) == (self.missing_reason is None):
            raise HistoryError(
                f"DiagnosticRow {self.name!r}: a value, or the reason it is missing (one of "
                f"the two), got value {self.value!r} and reason {self.missing_reason!r}"
            )
        if self.value is not None and (self.u_value is None or self.u_value < 0):
            raise HistoryError(
                f"DiagnosticRow.u_value must be a standard uncertainty >= 0 with the value of "
                f"{self.name!r}, got {self.u_value!r}"
            )


def _diagnostic_rows(where, rows):
    rows = tuple(rows)
    if not all(isinstance(r, DiagnosticRow) for r in rows):
        raise HistoryError(f"{where} must be DiagnosticRow, got {rows!r}")
    names = [r.name for r in rows]
    if len(set(names)) != len(names):
        raise HistoryError(f"{where} must not repeat a diagnostic, got {names!r}")
    return rows


@dataclass(frozen=True, kw_only=True)
class DiagnosticFitRow:
    """A night's diagnostic fit: the settings it ran with and every diagnostic of the set.

    A fit that failed keeps its row, its ``failure`` and every diagnostic
    with that reason: the night's squareness stands without it.

    Attributes
    ----------
    id : int or None
        Row id; None until stored.
    run_id : int or None
        The run it was fitted to; required by the store.
    settings : dict
        The diagnostic settings (effects, shapes, software), JSON values.
    settings_hash : str or None
        :func:`settings_hash` of ``settings``; computed when None.
    software_version : str
        imu-square's version that fitted it.
    fitted_at_ns : int or None
        When; stamped by the store when None. [ns]
    seconds : float or None
        The fit's time. [s]
    failure : str or None
        Why the fit gave nothing, one line; None when it ran.
    fit : dict
        The fit's own numbers (residual sum of squares, degrees of freedom,
        steps, simulator runs, ...), JSON values.
    values : tuple of DiagnosticRow
        Every diagnostic of the set (stored in the table ``diagnostics``).
    """

    id: int | None = _checked(default=None, minimum=1)
    run_id: int | None = _checked(default=None, minimum=1)
    settings: dict
    settings_hash: str | None = _checked(_sha256, default=None, required=False)
    software_version: str = __version__
    fitted_at_ns: int | None = None
    seconds: float | None = None
    failure: str | None = None
    fit: dict = field(default_factory=dict)
    values: tuple = _checked(_diagnostic_rows, default=())

    def __post_init__(self):
        _check_fields(self)
        if self.settings_hash is None:
            object.__setattr__(self, "settings_hash", settings_hash(self.settings))

    def value(self, name):
        """The :class:`DiagnosticRow` named ``name``, or None."""
        return next((v for v in self.values if v.name == name), None)
