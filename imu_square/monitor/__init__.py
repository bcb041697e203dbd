"""The squareness monitor: history, baseline, drift, alarms, alerts, metrics and report."""
