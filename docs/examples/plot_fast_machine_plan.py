"""
fast_machine_plan
=================

Placeholder.
"""

print("placeholder")
