"""The squareness monitor: a machine's baseline, its history, drift, alarms and alerts.

One module per idea. :mod:`imu_square.monitor.alarms` designs the control
charts on the standardised nightly change and evaluates a machine's nights;
:mod:`imu_square.monitor.arl` computes the charts' average run lengths and
:mod:`imu_square.monitor.charts` runs them on arrays of nights (also for Monte
Carlo).
"""
