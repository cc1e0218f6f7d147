"""What is soil: per-point labels from classification, colour and returns; objects and excluded
volumes for the volume step."""
