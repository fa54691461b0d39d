"""Identification of friction and damping from measured stick-slip records."""
