"""
ballbar_side_by_side
====================

Placeholder.
"""

print("placeholder")
