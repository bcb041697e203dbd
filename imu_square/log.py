"""The package logger. The library logs; only the CLI chooses a level and prints."""

import logging

logger = logging.getLogger("imu_square")
logger.addHandler(logging.NullHandler())
