"""Acquisition: serial accelerometer boards to MCAP recordings, and an emulated board.

This package may import :mod:`imu_square` (the recording format); the reverse
never happens.
"""
