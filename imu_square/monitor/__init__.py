"""The monitor: a machine's baseline, its history, thermal drift, designed alarms and alerts."""
