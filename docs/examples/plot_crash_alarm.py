"""
crash_alarm
===========

Placeholder.
"""

print("placeholder")
