"""
two_feeds
=========

Placeholder.
"""

print("placeholder")
