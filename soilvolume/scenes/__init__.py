"""Seeded synthetic before/after scenes with known volumes and the soilvolume demo command (not
part of the method).
"""
