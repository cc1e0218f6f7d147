"""Seeded synthetic scenes with known volumes, the demo and the self-test (not part of the method)."""
