"""Names vulture reports as unused that are used, where it cannot see them.

``python3 dev.py lint`` runs vulture (at 60 % confidence, which is every kind of
report: unused imports are ruff's) over ``imu_square/`` and ``acquisition/``
with this file. Vulture matches names only, so each line names the attribute
on ``_`` with the class or function it belongs to. Add a name here only with
its reason; code nothing uses is removed instead, and code only the tests use
lives in ``tests/``.
"""

# --- Called by Python or a library, not by our code ------------------------------------

# warnings.showwarning's signature, which cli._show_warning replaces.
_.showwarning
_.filename
_.file
# decimal's context precision, set in io/csv.py to read numbers exactly.
_.prec
# urllib.request.HTTPRedirectHandler.redirect_request, overridden by the webhook sink
# (monitor/alerts/webhook.py _RefuseRedirect) to refuse redirects.
_.redirect_request
_.req
_.newurl

# --- Fields written out by dataclasses.asdict / fields() or read by getattr ------------

# pipeline.result.DirectionResult: in RunResult.to_json_dict (analyze --json, the history).
_.outlier_fraction
# monitor.stats.alarms.ChartDesign and SchemeCheck: AlarmDesign.to_json_dict, by fields().
_.arl0_mean
_.arl1_mean
_.u_warning_fraction
_.u_arl1
_.u_arl1_steady
# monitor.stats.drift.DriftFit: to_json_dict by asdict (stored with each run).
_.slope_rad_per_unit
_.u_slope_rad_per_unit
_.value_at_reference_rad
_.u_value_at_reference_rad
_.uncorrected_rad
_.u_uncorrected_rad
# monitor.report.metrics.MetricsSnapshot: each metric's field read by getattr by name.
_.invalid_runs
_.last_run_at
_.last_valid_run_at

# --- The library's results, documented in their Attributes and read by their users ---
# (and by the tests); the product fills them but does not read them back itself.

# acquisition.protocol.ParserStats: the parser's counters (docs/protocol.md).
_.frames_ok
_.lines_ok
_.frames_ignored
_.bytes_discarded
# acquisition.trigger.MotionTrigger: the rest level it triggers against.
_.level_m_s2
# monitor.stats.baseline.Baseline: the span of runs it was set from.
_.first_recorded_at
_.last_recorded_at
# pipeline.sine_fit.CircleFit: the fitted offsets and the phases' uncertainties.
_.offset_x
_.offset_y
_.u_theta_x
_.u_theta_y
# reference.ballbar.BallbarResult.
_.machine_squareness_ccw_rad
_.machine_squareness_cw_rad
_.centre_offset_m
_.radius_change_m
_.scale_mismatch
_.deviation_ccw_m
_.deviation_cw_m
_.residual_rms_m
# reference.biaxial.BiaxialResult.
_.slope_x_rad
_.slope_y_rad
_.position_x_m
_.reading_x_m
_.position_y_m
_.reading_y_m
# reference.diagonal.DiagonalResult and DiagonalTest (ISO 230-6 E, B, E_d, B_d).
_.target_m
_.forward_error_m
_.reverse_error_m
_.length_m
_.e_d_m
_.b_d_m
# reference.step_diagonal.StepDiagonalResult.
_.commanded_m
_.moved_axis
_.reading_m
_.error_m
_.step_error_m
_.error_per_travel
_.diagonal_error_m

# --- Used by the benchmarks and the tests only --------------------------------------------

# simulate.effects.with_effect_values: benchmarks/discrepancy.py sets effects by it.
_.with_effect_values
# simulate.geometry.Geometry.axis_angle_y_to_x and acquisition.faults.FaultLog.seqs:
# methods the tests call (as a function in tests/ their calls, asserted on, would change).
_.axis_angle_y_to_x
_.seqs

# --- The history's rows and API --------------------------------------------------------

# monitor.history.rows: columns the converter (history/sql.Table) writes and reads by
# dataclasses.fields(); no code reads them by name.
_.software_version
_.cycles_ccw
_.cycles_cw
_.analysed_at_ns
_.claimed_by
_.claimed_until_ns
_.updated_at_ns
_.fitted_at_ns
# monitor.history: the schema's version, every table's columns and the machines of a
# central history, for a user's own scripts (and the tests that check the schema).
_.latest_version
_.COLUMNS
_.schema_version
_.machines
# program.planner.predict: what a given program resolves, the planner's API for a
# user's own program (plan_test chooses one).
_.predict
# monitor.history.store.History.baselines: every baseline of a machine, oldest first.
_.baselines
# linuxcnc.ini.LinuxcncLimits.arc_feed_m_s: the speed LinuxCNC runs a circle of a radius
# at, for a user checking a program against the machine (plan uses the arc acceleration).
_.arc_feed_m_s
# discrepancy.result.headline_is_honest: the headline rule (issue 22), checked on every
# case by benchmarks/discrepancy*.py and by the tests.
_.headline_is_honest
