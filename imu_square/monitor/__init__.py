"""The squareness monitor: a machine's baseline, its history, thermal drift,
designed alarms, alerts, metrics and the report (one module per idea)."""
