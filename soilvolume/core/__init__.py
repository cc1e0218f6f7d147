"""Shared building blocks every step depends on: plain data types and errors, run hooks, interrupt
flags, all-or-nothing outputs, native stderr capture.
"""
