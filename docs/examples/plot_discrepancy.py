"""
discrepancy
===========

Placeholder.
"""

print("placeholder")
