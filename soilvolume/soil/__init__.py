"""What is soil: per-point labels, objects and rough cells for the volume step."""
