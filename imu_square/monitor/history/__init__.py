"""The monitor's history: rows, schema, and one store over SQLite and PostgreSQL."""
