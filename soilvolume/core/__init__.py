"""Shared building blocks: data types and errors, run hooks, interrupts, all-or-nothing outputs."""
