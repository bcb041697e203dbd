"""The monitor's statistics: baseline, change, thermal drift, alarm charts and their design."""
