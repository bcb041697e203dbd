"""Subcommands of ``imu-square``: one module each, with ``register(subparsers)``."""
