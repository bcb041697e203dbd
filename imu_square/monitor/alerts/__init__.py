"""Alerts: what a night sends, its sinks (webhook, e-mail, JSON file, log), their delivery."""
